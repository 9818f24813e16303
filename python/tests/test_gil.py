"""fk releases the GIL: another Python thread keeps running during a solve."""

import threading
import time

import numpy as np

import tendril


def test_a_python_thread_keeps_counting_during_a_long_fk():
    robot = tendril.Robot.default()
    tensions = np.random.default_rng(2).uniform(0, 10, (50, 4))
    count = 0
    stop = threading.Event()

    def counter():
        nonlocal count
        while not stop.is_set():
            count += 1

    thread = threading.Thread(target=counter)
    thread.start()
    try:
        time.sleep(0.05)
        before = count
        start = time.perf_counter()
        _, converged = robot.fk(tensions, steps=400)
        seconds = time.perf_counter() - start
        during = count - before
    finally:
        stop.set()
        thread.join()
    assert converged.all()
    # A call holding the GIL would let the counter run only at its edges
    # (a handful of increments); released, it counts all the way through.
    assert seconds > 0.05, f"fk took {seconds:.3f} s: too short to tell"
    assert during > 1_000, f"counter advanced {during} times in {seconds:.2f} s of fk"
