#!/usr/bin/env bash
# The README's looping animation of the demo: frames of the pool rendered headless
# (`demo --sequence`), assembled into a GIF at half size with ImageMagick (installed
# with apt-get when missing). Writes target/animation/demo.gif, or the path given.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/animation/demo.gif}"
frames="$(dirname "$out")/frames"
rm -rf "$frames" && mkdir -p "$frames"
if ! dpkg -s imagemagick > /dev/null 2>&1; then
    apt-get install -y imagemagick
fi
# The shower's ripples, the shafts under them and the ball bobbing: 36 frames 50 ms
# apart, shown as fast as they were made (20 a second).
cargo run --locked --example demo -- --headless --frames 4 --sequence 36 --out "$frames/frame.png"
convert -delay 5 -loop 0 "$frames"/frame-*.png -resize 50% -layers Optimize "$out"
echo "wrote $out ($(du -h "$out" | cut -f1))"
