#!/usr/bin/env bash
# Vendors three.js for `lgi view` from the npm registry: scripts/vendor_three.sh [VERSION].
set -euo pipefail
version="${1:-0.187.0}"
dest="$(cd "$(dirname "$0")/.." && pwd)/python/lgi/review/viewer/three"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
(cd "$work" && npm pack "three@$version" --silent >/dev/null && tar xzf "three-$version.tgz")
cp "$work/package/build/three.module.js" "$work/package/build/three.core.js" \
   "$work/package/examples/jsm/controls/OrbitControls.js" "$work/package/LICENSE" "$dest/"
(cd "$dest" && sha256sum three.module.js three.core.js OrbitControls.js > SHA256SUMS)
sed -i "s/three@[0-9.]*/three@$version/" "$dest/README.md"
echo "vendored three@$version into $dest"
