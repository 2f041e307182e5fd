"""The timing rule every side-by-side benchmark here shares: both sides are
timed round by round in turn, after one warm-up round each, so that whatever
else the machine does falls on both alike. A round runs every item once; our
side's rounds run in `ort_bench serve` (`train-host/eval/examples/ort_bench.rs`),
kept waiting between them. The results are each side's median round and best
(fastest) round, in milliseconds per item."""

import subprocess
import time

ROUNDS = 9


class Ours:
    """Our side of a benchmark: `ort_bench serve DIR`, one round per request."""

    def __init__(self, exe, root):
        self.proc = subprocess.Popen(
            [str(exe), "serve", str(root)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )

    def round(self, request):
        """One round of `request` (e.g. `embedded int8`, `icp fixed`): its
        milliseconds per call, as our side measured them."""
        self.proc.stdin.write(request + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise SystemExit(f"our benchmark side stopped on {request!r} (its error is above)")
        return float(line)

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def time_round(call, items):
    """`call(item)` for every item once: milliseconds per item."""
    t = time.perf_counter()
    for item in items:
        call(item)
    return (time.perf_counter() - t) * 1e3 / len(items)


def paired(ours, theirs, rounds=ROUNDS):
    """One warm-up round of each side (`ours()`, `theirs()`: one round, its
    milliseconds per item), then `rounds` timed rounds of each in turn, ours
    first in even rounds and theirs first in odd ones. Returns ((median,
    best) of ours, (median, best) of theirs)."""
    ours()
    theirs()
    mine, other = [], []
    for r in range(rounds):
        if r % 2 == 0:
            mine.append(ours())
            other.append(theirs())
        else:
            other.append(theirs())
            mine.append(ours())
    return summary(mine), summary(other)


def summary(times):
    """(median, best) of round times."""
    times = sorted(times)
    return times[len(times) // 2], times[0]
