#!/usr/bin/env python3
"""Times commands side by side: N rounds, each command once per round in turn, and prints for
each the median wall time and the median CPU time (user + system, from the kernel's rusage) in
ms. Usage: time_runs.py N LABEL 'COMMAND' [LABEL 'COMMAND' ...] (commands run through sh,
their output discarded; a run that exits non-zero is noted and still timed)."""
import os
import statistics
import subprocess
import sys
import time

FAILED = set()


def run(command):
    """Wall time and user + system CPU time [s] of one run of `command`."""
    start = time.perf_counter()
    proc = subprocess.Popen(command, shell=True, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    code = os.waitstatus_to_exitcode(status)
    if code != 0 and command not in FAILED:
        FAILED.add(command)
        print(f"note: exit status {code}: {command}", file=sys.stderr)
    return wall, usage.ru_utime + usage.ru_stime


def main():
    n = int(sys.argv[1])
    pairs = list(zip(sys.argv[2::2], sys.argv[3::2]))
    times = {label: [] for label, _ in pairs}
    for _ in range(n):
        for label, command in pairs:
            times[label].append(run(command))
    print(f"{'':<10} {'wall ms':>9} {'cpu ms':>9}   (medians of {n} runs)")
    for label, _ in pairs:
        wall = statistics.median(t[0] for t in times[label]) * 1e3
        cpu = statistics.median(t[1] for t in times[label]) * 1e3
        print(f"{label:<10} {wall:>9.1f} {cpu:>9.1f}")


main()
