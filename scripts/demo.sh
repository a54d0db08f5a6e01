#!/usr/bin/env bash
# Set up and run the main job on the bundled example without hardware.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
fivebar config check configs/default.toml
fivebar ik 20 100
fivebar fk 139.866 40.134
