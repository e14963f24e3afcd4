"""What the parametric bootstrap of 100,000 ten-epoch segments would cost batched over
all of them (issue 35, the ten-epoch target; docs/performance.md, session 29).

    python benchmarks/bootstrap_cost.py [--segments S] [--chunk C]

Per segment 3 series (two directions and the centred NEES), of which 79 % are fitted with
memory (measured on 2,000 credible ten-epoch segments), 40 replicates each
(``memory.BOOTSTRAP_REPLICATES``): AR(1) series with φ drawn in [−0.5, 0.9], a burn-in
of 20 epochs, centred, refitted by the engine's own :func:`credcli.engine.memory.burg`
(orders 1 … 2, as at N = 10), their τ and τ₂ by the engine's ``_log_taus`` and
``_square_ratios``. Prints the CPU of each step. A measurement, not a test.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from credcli.engine import memory


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--segments", type=int, default=100_000)
    ap.add_argument("--chunk", type=int, default=400_000, help="series batched at a time")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    series = int(args.segments * 3 * 0.79) * memory.BOOTSTRAP_REPLICATES
    steps = dict.fromkeys(("draw", "filter", "burg", "log tau", "tau2"), 0.0)
    start, done = time.process_time(), 0
    while done < series:
        m = min(args.chunk, series - done)
        done += m
        phi = rng.uniform(-0.5, 0.9, m)
        t0 = time.process_time()
        z = rng.standard_normal((m, 30))
        t1 = time.process_time()
        x = np.empty_like(z)
        x[:, 0] = z[:, 0]
        for t in range(1, 30):
            x[:, t] = phi * x[:, t - 1] + z[:, t]
        x = x[:, 20:] - x[:, 20:].mean(axis=1, keepdims=True)
        t2 = time.process_time()
        fit = memory.burg(np.ascontiguousarray(x).reshape(m, 1, 10), 2)
        orders = fit.orders(1)
        t3 = time.process_time()
        memory._log_taus(fit.reflection, orders)
        t4 = time.process_time()
        memory._square_ratios(fit.reflection, orders)
        t5 = time.process_time()
        for key, dt in zip(steps, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4)):
            steps[key] += dt
    parts = ", ".join(f"{k} {v:.1f} s" for k, v in steps.items())
    print(f"{series:,} bootstrap series: {time.process_time() - start:.1f} s CPU ({parts})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
