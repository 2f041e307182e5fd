"""The timing rule every side-by-side benchmark here shares with ours
(`train-host/examples/ort_bench.rs`): one warm-up round over all items,
then `rounds` timed rounds; the results are the median round's and the
best (fastest) round's time per item, in milliseconds."""

import time


def round_ms(call, items, rounds):
    """`call(item)` for every item, `rounds + 1` times; the median and the
    best timed round's milliseconds per item (the first round is the
    warm-up)."""
    times = []
    for r in range(rounds + 1):
        t = time.perf_counter()
        for item in items:
            call(item)
        if r > 0:
            times.append((time.perf_counter() - t) * 1e3 / len(items))
    times.sort()
    return times[len(times) // 2], times[0]
