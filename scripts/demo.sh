#!/usr/bin/env bash
# Set up and run the main job on the bundled example without hardware: check the machine
# profile, compile and check the drawing (report + preview.png), then plot it on the real
# firmware running in the simavr emulator and measure what its step pulses drew.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
make -s -C firmware all sim >/dev/null
echo "== the machine profile"
fivebar config check configs/default.toml | head -8
echo "== dry run: compile, check, time and validate (writes preview.png)"
fivebar plot examples/fivebar_text.svg --dry-run --preview preview.png
echo "== plot on the emulated firmware, in real time: stream, then measure its step pulses"
fivebar plot examples/fivebar_text.svg --port "fivebar-sim://?realtime=1" --yes --preview preview.png
echo "== a drawing no single working mode can draw: --mode auto plans pen-up mode changes"
fivebar plot examples/mode_change.gcode --origin 0,0 --mode auto --dry-run \
  --preview "${TMPDIR:-/tmp}/mode_change.png" | grep -E "^(working mode|mode change|deviation)"
