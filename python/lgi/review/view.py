"""`lgi view`: a solved take in the browser. A small HTTP server on 127.0.0.1 serves one page
(`lgi/review/viewer/index.html`, three.js vendored beside it) and the take in pieces: the
faces once,
then frames in chunks as the page plays or seeks, so a 1,500-frame ICT take shows its first
frame without sending half a gigabyte. Colours per vertex (displacement from the first frame,
or the distance to a second solve: A/B) are computed here, per chunk. The page also carries the
marker x frame residual heatmap and the worst frames; clicking either seeks. `/report.html`
is `lgi report`'s page whose worst-frame entries open the viewer at that frame."""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any, cast
from urllib.parse import parse_qs, urlsplit

import numpy as np

from lgi.errors import InputError
from lgi.io.result import Result, stream_result_npz

__all__ = ["CHUNK_FRAMES", "ViewData", "serve"]

CHUNK_FRAMES = 32
"""Frames per request: 32 ICT frames are 10 MB of float32 positions."""

_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8"}


@dataclass
class ViewData:
    """What the page asks for, from a solved take and optionally a second solve (A/B)."""

    solved: Result
    source: str
    reference: Result | None = None
    reference_label: str = ""
    wait: Callable[[int], None] = field(default=lambda _stop: None)
    """Returns once the solve's frames 0..stop-1 are read (`stream_result_npz`)."""
    reference_wait: Callable[[int], None] = field(default=lambda _stop: None)

    def __post_init__(self) -> None:
        if self.reference is not None and self.reference.vertices.shape != (
            self.solved.vertices.shape
        ):
            raise InputError(
                f"--compare {self.reference_label}: {self.reference.vertices.shape[0]} frames of "
                f"{self.reference.vertices.shape[1]} vertices, the solve has "
                f"{self.solved.vertices.shape[0]} frames of {self.solved.vertices.shape[1]}; "
                "compare solves of the same mesh and frames"
            )
        self._triangles = self.solved.topology.triangles().astype(np.uint32)

    @property
    def num_frames(self) -> int:
        return int(self.solved.vertices.shape[0])

    def meta(self) -> dict[str, Any]:
        from lgi.review.report import WORST_SHOWN, worst_frames

        s = self.solved
        return {
            "source": os.path.basename(self.source),
            "frames": self.num_frames,
            "start": s.start,
            "fps": s.fps or 24.0,
            "fps_known": s.fps is not None,
            "units": s.units or "",
            "vertices": int(s.vertices.shape[1]),
            "triangles": int(self._triangles.shape[0]),
            "markers": list(s.marker_names),
            "has_markers": s.markers is not None,
            "reference": self.reference_label if self.reference is not None else None,
            "chunk": CHUNK_FRAMES,
            "worst_frames": [
                {"frame": w.frame, "residual": w.residual, "marker": s.marker_names[w.marker]}
                for w in worst_frames(s, WORST_SHOWN)
            ],
            "repairs": []
            if s.settings is None
            else [
                {"markers": list(markers), "first": first, "last": last, "line": line}
                for (_, markers, first, last), line in zip(
                    s.settings.repairs, s.settings.repair_lines(s.start), strict=True
                )
            ],
        }

    def triangles(self) -> bytes:
        return self._triangles.tobytes()

    def residuals(self) -> bytes:
        """(F, B) float32, NaN where missing."""
        s = self.solved
        return np.where(s.missing, np.nan, s.bundle_residuals).astype("<f4").tobytes()

    def _span(self, start: int) -> slice:
        if not 0 <= start < self.num_frames or start % CHUNK_FRAMES:
            raise InputError(f"chunk start {start} is not a chunk of 0..{self.num_frames - 1}")
        return slice(start, min(start + CHUNK_FRAMES, self.num_frames))

    def positions(self, start: int) -> bytes:
        self.wait(self._span(start).stop)
        return np.ascontiguousarray(self.solved.vertices[self._span(start)], "<f4").tobytes()

    def markers(self, start: int) -> bytes:
        if self.solved.markers is None:
            raise InputError("the solved take holds no marker positions")
        return np.ascontiguousarray(self.solved.markers[self._span(start)], "<f4").tobytes()

    def colours(self, mode: str, start: int) -> bytes:
        """Per-vertex scalars of the chunk (n, V) float32: `displacement` (distance to the
        first frame) or `difference` (distance to the reference solve)."""
        span = self._span(start)
        self.wait(span.stop)
        v = self.solved.vertices[span].astype(np.float32)
        if mode == "displacement":
            base = self.solved.vertices[:1].astype(np.float32)
        elif mode == "difference" and self.reference is not None:
            self.reference_wait(span.stop)
            base = self.reference.vertices[span].astype(np.float32)
        else:
            raise InputError(f"no colour {mode!r} for this take")
        return np.linalg.norm(v - base, axis=2).astype("<f4").tobytes()


def _page_file(name: str) -> bytes:
    """A file of the page (index.html, viewer.js, three/...): package data, never outside it."""
    parts = [p for p in name.split("/") if p]
    if not parts or any(p in (".", "..") or p.startswith(".") for p in parts):
        raise FileNotFoundError(name)
    node = resources.files("lgi.review") / "viewer"
    for p in parts:
        node = node / p
    return node.read_bytes()


def _own_host(host: str | None, port: int) -> bool:
    """Whether a request's Host header names the viewer itself: the loopback address (or
    `localhost`) and the port it serves, as the browser sends it for `serve`'s address."""
    return host in {f"127.0.0.1:{port}", f"localhost:{port}"}


def _handler(data: ViewData, report: Callable[[], str]) -> type[BaseHTTPRequestHandler]:
    made: list[bytes] = []
    lock = threading.Lock()

    def report_page() -> bytes:
        with lock:  # made once, on first request: a 1,500-frame report takes seconds
            if not made:
                made.append(report().encode())
            return made[0]

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, format: str, *args: Any) -> None:
            pass  # a viewer's access log is noise in a TD's terminal

        def _send(self, body: bytes, kind: str, status: int = HTTPStatus.OK) -> None:
            self.send_response(status)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def do_GET(self) -> None:
            port = cast("tuple[str, int]", self.server.server_address)[1]
            if not _own_host(self.headers.get("Host"), port):
                # DNS rebinding: a page elsewhere whose name now points at 127.0.0.1 reaches
                # this port with its own Host; only the viewer's own address is served.
                self._send(b"this host is not the viewer's", "text/plain", HTTPStatus.FORBIDDEN)
                return
            url = urlsplit(self.path)
            q = {k: v[-1] for k, v in parse_qs(url.query).items()}
            try:
                start = int(q.get("start", "0"))
                path = url.path
                if path in ("/", "/index.html"):
                    self._send(_page_file("index.html"), _TYPES[".html"])
                elif path == "/report.html":
                    self._send(report_page(), _TYPES[".html"])
                elif path == "/meta.json":
                    self._send(json.dumps(data.meta()).encode(), "application/json")
                elif path == "/triangles.bin":
                    self._send(data.triangles(), "application/octet-stream")
                elif path == "/residuals.bin":
                    self._send(data.residuals(), "application/octet-stream")
                elif path == "/positions.bin":
                    self._send(data.positions(start), "application/octet-stream")
                elif path == "/markers.bin":
                    self._send(data.markers(start), "application/octet-stream")
                elif path == "/colours.bin":
                    self._send(data.colours(q.get("mode", ""), start), "application/octet-stream")
                elif path == "/favicon.ico":
                    self._send(b"", "image/x-icon", HTTPStatus.NO_CONTENT)
                else:
                    body = _page_file(path.lstrip("/"))
                    self._send(body, _TYPES.get(Path(path).suffix, "application/octet-stream"))
            except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
                self._send(b"not found", "text/plain", HTTPStatus.NOT_FOUND)
            except (InputError, ValueError) as e:
                self._send(str(e).encode(), "text/plain", HTTPStatus.BAD_REQUEST)

    return Handler


def serve(data: ViewData, *, port: int = 0) -> tuple[ThreadingHTTPServer, str]:
    """Starts the viewer's server on 127.0.0.1 (`port` 0: any free port) in a daemon thread;
    returns it and its address. `/report.html` is `lgi report`'s page of the take, its worst
    frames linking back to the viewer."""
    from lgi.review.report import render_report
    from lgi.solve.diagnose import finding_lines

    def report() -> str:
        data.wait(data.num_frames)
        data.reference_wait(data.num_frames)
        s = data.solved
        found = finding_lines(s)
        return render_report(
            data.solved,
            source=data.source,
            reference=data.reference,
            reference_label=data.reference_label,
            viewer_url="/",
            findings=found,
        )

    try:
        server = ThreadingHTTPServer(("127.0.0.1", port), _handler(data, report))
    except OSError as e:
        raise InputError(f"--port {port}: cannot listen on 127.0.0.1: {e.strerror}") from None
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/"


def load(solved: str | os.PathLike[str], compare: str | os.PathLike[str] | None = None) -> ViewData:
    """The view of a solved `.npz` (and a second solve to colour the difference to)."""
    s, wait = _open(solved)
    ref, ref_wait = (None, _ready) if compare is None else _open(compare)
    return ViewData(
        s,
        os.fspath(solved),
        ref,
        "" if compare is None else Path(compare).name,
        wait=wait,
        reference_wait=ref_wait,
    )


def _open(path: str | os.PathLike[str]) -> tuple[Result, Callable[[int], None]]:
    """A `.npz` streamed (`stream_result_npz`); a USD cache read whole (`read_usd_cache`)."""
    from lgi.review.report import USD_SUFFIXES

    if Path(path).suffix.lower() in USD_SUFFIXES:
        from lgi.io.usd import read_usd_cache

        return read_usd_cache(path), _ready
    return stream_result_npz(path)


def _ready(_stop: int) -> None:
    """`ViewData.wait` of arrays read whole."""
