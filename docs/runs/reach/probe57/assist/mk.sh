#!/usr/bin/env bash
# mk.sh NAME OFFSETS_TOML|none STIFF DAMP SUPK SUPD SUPH : a copy of the committed default with the
# offsets overlay appended and [sim.assist] set.
set -euo pipefail
name=$1; off=$2; k=$3; d=$4; sk=$5; sd=$6; sh=$7
src=/work/main/docs/runs/reach/scratch-line-acc80
dst=/work/probe57/$name
rm -rf "$dst"; cp -r "$src" "$dst"
python3 - "$dst/config.toml" "$k" "$d" "$sk" "$sd" "$sh" <<'PY'
import sys, re
p, k, d, sk, sd, sh = sys.argv[1:]
t = open(p).read()
new = f"[sim.assist]\nstiffness = {k}\ndamping = {d}\nsupport_stiffness = {sk}\nsupport_damping = {sd}\nsupport_height = {sh}\nfade_from = 0\nfade_to = 0\n"
t2, n = re.subn(r"\[sim\.assist\]\n(?:[a-z_]+ = [^\n]*\n)+", new, t)
assert n == 1, n
open(p, "w").write(t2)
PY
if [ "$off" != none ]; then
  grep -v '^#' "$off" | sed -n '/^\[env.gait.angle_offsets\]/,$p' >> "$dst/config.toml"
fi
python3 -c "import tomllib,sys; c=tomllib.load(open('$dst/config.toml','rb')); print('$name', c['sim']['assist'], len(c['env']['gait'].get('angle_offsets',{})))"
