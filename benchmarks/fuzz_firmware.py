"""Fuzz the firmware's line parser with libFuzzer and print the figures.

Builds firmware/fuzz/fuzz_parser.c twice with clang (``make -C firmware fuzz fuzz-parser``,
both with AddressSanitizer and UndefinedBehaviorSanitizer) and runs, on one core:

1. ``fuzz_parser_only`` (the target's framing part: every line through ``proto_parse_line``
   with its invariants — defined status, resends leave the counter, strict framing, a line
   with a ``*`` passes only with the host's exact field, a line that lost its ``N`` and ``*``
   is never accepted) for ``--runs`` executions (10 M by default);
2. ``fuzz_parser`` (the same, plus every input fed through the whole firmware on the fake
   board with simulated time) for ``--full-seconds``: about 50 times slower per execution,
   so it gets a time budget instead.

For each it prints executions, executions per second, libFuzzer's coverage (``cov``: code
edges reached, ``ft``: features) and the crashes (inputs libFuzzer saved as crash-, leak-,
timeout- or oom- artifacts, or a non-zero exit).  Both start from firmware/fuzz/corpus; new
inputs go to a temporary directory, so the committed corpus stays as it is.  Not part of
the test run: ``python benchmarks/fuzz_firmware.py [--runs N] [--full-seconds S]``.
Needs ``clang`` and ``libclang-rt-14-dev``.  Exits 1 if anything crashed.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware"
CORPUS = FIRMWARE / "fuzz" / "corpus"
ARTIFACTS = ("crash-", "leak-", "timeout-", "oom-", "slow-unit-")


@dataclass(frozen=True)
class FuzzResult:
    """The figures of one libFuzzer run."""

    name: str
    executions: int
    exec_per_s: int
    seconds: float
    cov: int
    ft: int
    crashes: int
    returncode: int


def build() -> None:
    """Build both fuzz targets; exit with make's output when that fails."""
    proc = subprocess.run(["make", "-s", "-C", str(FIRMWARE), "fuzz", "fuzz-parser"],
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        sys.exit(f"fuzz build failed (needs: apt-get install clang libclang-rt-14-dev):\n"
                 f"{proc.stdout}{proc.stderr}")


def run_fuzzer(name: str, limit: list[str], max_len: int, seed: int) -> FuzzResult:
    """Run ``firmware/build/host/<name>`` with the ``limit`` flags; parse its final stats."""
    binary = FIRMWARE / "build" / "host" / name
    with tempfile.TemporaryDirectory(prefix="fivebar-fuzz-") as tmp:
        work = Path(tmp) / "corpus"
        work.mkdir()
        arts = Path(tmp) / "artifacts"
        arts.mkdir()
        cmd = [str(binary), *limit, f"-max_len={max_len}", f"-seed={seed}",
               "-print_final_stats=1", f"-artifact_prefix={arts}/", str(work), str(CORPUS)]
        print("  $ " + " ".join(cmd), flush=True)
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        log = proc.stderr
        crashes = sum(1 for p in arts.iterdir() if p.name.startswith(ARTIFACTS))
    stats = dict(re.findall(r"^stat::(\w+):\s+(\d+)", log, re.MULTILINE))
    done = re.findall(r"^#(\d+)\s+DONE\s+cov: (\d+) ft: (\d+)", log, re.MULTILINE)
    last = re.findall(r"^#(\d+)\s+\w+\s+cov: (\d+) ft: (\d+)", log, re.MULTILINE)
    execs, cov, ft = (int(v) for v in (done or last or [("0", "0", "0")])[-1])
    secs = re.findall(r"^Done \d+ runs in (\d+) second", log, re.MULTILINE)
    if proc.returncode != 0 and crashes == 0:
        crashes = 1  # it stopped on a finding without saving it
    if proc.returncode != 0:
        print(log[-4000:], file=sys.stderr)
    return FuzzResult(name, int(stats.get("number_of_executed_units", execs)),
                      int(stats.get("average_exec_per_sec", 0)),
                      float(secs[-1]) if secs else 0.0, cov, ft, crashes, proc.returncode)


def show(r: FuzzResult) -> None:
    """Print one run's figures."""
    print(f"  {r.name}: {r.executions:,} executions in {r.seconds:.0f} s "
          f"({r.exec_per_s:,} exec/s), cov {r.cov}, ft {r.ft}, crashes {r.crashes}", flush=True)


def main() -> int:
    """Build, run both targets, print the figures; 1 if anything crashed."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=10_000_000,
                    help="executions of the parser-only target (default 10,000,000)")
    ap.add_argument("--full-seconds", type=int, default=60,
                    help="seconds for the whole-firmware target (default 60; 0 skips it)")
    ap.add_argument("--max-len", type=int, default=256, help="longest input, bytes")
    ap.add_argument("--seed", type=int, default=1, help="libFuzzer's random seed")
    args = ap.parse_args()
    build()
    print(f"fivebar firmware fuzzing (libFuzzer, ASan + UBSan, one core, seed corpus "
          f"{len(list(CORPUS.iterdir()))} inputs)", flush=True)
    results = [run_fuzzer("fuzz_parser_only", [f"-runs={args.runs}"], args.max_len, args.seed)]
    show(results[-1])
    if args.full_seconds > 0:
        results.append(run_fuzzer("fuzz_parser", [f"-max_total_time={args.full_seconds}"],
                                  args.max_len, args.seed))
        show(results[-1])
    total = sum(r.crashes for r in results)
    print(f"  total: {sum(r.executions for r in results):,} executions, {total} crashes")
    return 1 if total else 0


if __name__ == "__main__":
    sys.exit(main())
