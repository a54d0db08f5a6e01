#!/usr/bin/env bash
# Set up and run the main job on the bundled example without hardware.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
fivebar config check configs/default.toml
fivebar ik 20 100
fivebar fk 139.866 40.134
# The job pipeline on a bundled drawing: compile, check, time and validate, no hardware.
fivebar plot examples/fivebar_text.svg --dry-run --preview preview.png
fivebar convert examples/simple.svg -o "${TMPDIR:-/tmp}/simple.job.gcode"
# A drawing no single working mode can draw: --mode auto plans pen-up mode changes.
fivebar plot examples/mode_change.gcode --origin 0,0 --mode auto --dry-run \
  --preview "${TMPDIR:-/tmp}/mode_change.png"
