#!/usr/bin/env bash
# Writes assets/models/bunny.obj from the npm package `bunny` (the Stanford bunny of the
# Stanford 3D Scanning Repository, reduced to 1839 vertices and 3674 triangles; the
# package is public domain): closed, wound counter-clockwise outwards, y up, standing on
# y = 0. Needs npm and node.
set -euo pipefail
cd "$(dirname "$0")/.."
work=$(mktemp -d)
(cd "$work" && npm pack bunny@1.0.1 >/dev/null && tar xzf bunny-1.0.1.tgz)
node -e '
const b = require(process.argv[1]);
const lines = ["# The Stanford bunny (Stanford 3D Scanning Repository), from the public-domain npm package bunny@1.0.1.",
  "# " + b.positions.length + " vertices, " + b.cells.length + " triangles, counter-clockwise outwards, y up, units as in the package."];
for (const p of b.positions) lines.push("v " + p.map(x => x.toFixed(6)).join(" "));
for (const c of b.cells) lines.push("f " + c.map(i => i + 1).join(" "));
require("fs").writeFileSync("assets/models/bunny.obj", lines.join("\n") + "\n");
' "$work/package"
rm -rf "$work"
echo "wrote assets/models/bunny.obj"
