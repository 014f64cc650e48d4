"""Heavy native calls release the GIL: another Python thread keeps running meanwhile."""

from __future__ import annotations

import threading
import time

import numpy as np

import actrack


def test_inference_releases_the_gil():
    n, d = 30, 9
    trans = np.eye(n) * 0.9 + np.eye(n, k=1) * 0.1
    trans[-1, -1] = 1.0
    model = actrack.Hmm.from_params(
        np.eye(n)[0], trans, np.arange(n * d, dtype=float).reshape(n, d) / 10, np.stack([np.eye(d)] * n)
    )
    x = np.random.default_rng(0).normal(size=(50_000, d))
    started, done = threading.Event(), threading.Event()
    elapsed = []

    def work():
        started.set()
        t0 = time.perf_counter()
        model.posteriors(x)  # one long native call
        elapsed.append(time.perf_counter() - t0)
        done.set()

    worker = threading.Thread(target=work)
    ticks = 0
    worker.start()
    started.wait()
    while not done.is_set():
        ticks += 1
    worker.join()
    # Holding the GIL for the whole call, the worker would keep this loop from running at all.
    assert elapsed[0] > 0.05
    assert ticks > 1000
