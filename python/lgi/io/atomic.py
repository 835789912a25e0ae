"""Files written whole or not at all, the one way every writer of the package does it: the
bytes go to a hidden temporary name beside the target (same folder, so the rename is atomic;
the target's suffix kept, since USD and numpy choose a format by it), are flushed to disk, and
the temporary is renamed onto the target. Any exception on the way, Ctrl-C included, removes
the temporary and leaves the target as it was. An OBJ sequence, many files, is written into a
hidden folder beside it and moved into place once complete, after the old sequence of the same
name is removed, so two sequences never mix. The core's model file follows the same rule
(`crates/lgi-core/src/io/atomic.rs`)."""

from __future__ import annotations

import os
import re
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from lgi.errors import FileWriteError, InputError

__all__ = [
    "atomic_path",
    "check_writable",
    "discard_staging",
    "existing_sequence",
    "ready_folder",
    "refuse_existing",
    "replace_sequence",
    "sequence_staging",
    "temporary_beside",
    "writable_folder",
    "write_text",
]


def temporary_beside(target: Path, *, folder: bool = False) -> Path:
    """A fresh hidden name beside `target`: `.NAME.PID.RANDOM.tmp.SUFFIX` (a folder:
    `.NAME.PID.RANDOM.tmp.d`)."""
    tag = f"{os.getpid()}.{secrets.token_hex(4)}"
    end = ".tmp.d" if folder else f".tmp{target.suffix}"
    return target.with_name(f".{target.stem}.{tag}{end}")


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def atomic_path(target: str | os.PathLike[str]) -> Iterator[Path]:
    """Yields a temporary path beside `target` to write; when the block ends normally the
    file is synced and renamed onto `target`, otherwise (an exception, Ctrl-C) removed. A
    target that is a device or a pipe (`/dev/stdout`) is written in place instead: renaming
    over it would replace the device."""
    t = Path(target)
    if t.exists() and not t.is_file() and not t.is_dir():
        yield t
        return
    if t.is_symlink():
        t = t.resolve()  # the link stays; the file it names is replaced
    tmp = temporary_beside(t)
    try:
        yield tmp
        if not tmp.exists():
            raise FileWriteError(f"cannot write {t}: the writer produced no file")
        _fsync(tmp)
        os.replace(tmp, t)
    except OSError as e:
        raise FileWriteError(f"cannot write {t}: {e.strerror or e}") from None
    finally:
        tmp.unlink(missing_ok=True)


def write_text(target: str | os.PathLike[str], text: str) -> None:
    """`text` (UTF-8) written whole to `target` or not at all (`atomic_path`)."""
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")


def check_writable(target: str | os.PathLike[str], what: str = "--out") -> None:
    """Fails now, before any work, if a file cannot be created beside `target` (a read-only
    folder, a full disk's quota, a folder that vanished): a probe file is made and removed."""
    t = Path(target)
    probe = temporary_beside(t)
    try:
        probe.touch(exist_ok=False)
    except OSError as e:
        raise FileWriteError(
            f"{what} {t}: cannot write to the folder {t.parent.resolve()}: "
            f"{(e.strerror or str(e)).lower()}"
        ) from None
    probe.unlink(missing_ok=True)


def refuse_existing(target: Path, what: str, force: bool) -> None:
    """An existing output is replaced only with `--force`."""
    if not force and (target.exists() or target.is_symlink()):
        raise InputError(f"{what} {target}: exists (use --force to replace it)")


def ready_folder(out: Path, force: bool, what: str = "--out") -> Path:
    """An output folder a command writes several files into (`lgi demo`, `evaluate`,
    `helmet-demo`): created when missing; one that already holds anything is written into only
    with `force` (files of the same names are then replaced, others left as they are), so a
    second run never replaces the first one's results unasked; checked writable now, before
    any work (`check_writable`)."""
    if out.is_dir() and not force:
        held = sorted(p.name for p in out.iterdir())
        if held:
            shown = ", ".join(held[:3]) + (", ..." if len(held) > 3 else "")
            raise InputError(
                f"{what} {out}: the folder already holds {len(held)} "
                f"entr{'y' if len(held) == 1 else 'ies'} ({shown}); use --force to write into "
                "it (files of the same names are replaced) or give a new or empty folder"
            )
    writable_folder(out, what)
    return out


def writable_folder(out: Path, what: str, probe: str = "probe") -> None:
    """Creates folder `out` (and its parents) when missing and checks now that a file (named
    like `probe`) can be written in it; FileWriteError naming `what` otherwise."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise FileWriteError(f"{what} {out}: cannot create the folder: {e.strerror or e}") from None
    check_writable(out / probe, what)


def _frame_pattern(stem: str) -> re.Pattern[str]:
    return re.compile(re.escape(stem) + r"\.-?\d+\.obj\Z")


def existing_sequence(folder: Path, stem: str) -> list[Path]:
    """The frames of an OBJ sequence `STEM.NNNN.obj` already in `folder`."""
    if not folder.is_dir():
        return []
    pat = _frame_pattern(stem)
    return sorted(p for p in folder.iterdir() if pat.match(p.name))


def sequence_staging(folder: Path, stem: str) -> Path:
    """A hidden folder beside the sequence to write its frames into (created)."""
    folder.mkdir(parents=True, exist_ok=True)
    stage = temporary_beside(folder / stem, folder=True)
    stage.mkdir()
    return stage


def replace_sequence(stage: Path, folder: Path, stem: str) -> None:
    """Moves a complete sequence from `stage` into `folder`, removing the old frames of the
    same name first (so the folder never holds two sequences' frames), then the stage."""
    try:
        for old in existing_sequence(folder, stem):
            old.unlink()
        for new in sorted(stage.iterdir()):
            os.replace(new, folder / new.name)
    except OSError as e:
        raise FileWriteError(f"cannot write the sequence {folder / stem}: {e.strerror}") from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def discard_staging(stage: Path) -> None:
    """Removes a sequence's stage after a failure or an interrupt."""
    shutil.rmtree(stage, ignore_errors=True)
