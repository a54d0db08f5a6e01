"""`python -m benchmarks.speed_accuracy [--out-dir docs] [--quick]`: see `run.main`."""

from benchmarks.speed_accuracy.run import main

main()
