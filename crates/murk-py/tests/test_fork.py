"""Fork safety and murk.Augment's determinism."""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import signal

import numpy as np
import pytest

import murk
from conftest import TABLE_JSON, scan

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")


def test_apply_in_a_forked_child_after_the_parent_used_its_pools(table):
    pts = scan(200000, seed=11)
    want = murk.apply(pts, table, "fog", mor=50, range_noise=0.03, seed=1, threads=2).tobytes()
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: a deadlock here is killed by the alarm
        try:
            signal.alarm(60)
            got = murk.apply(pts, table, "fog", mor=50, range_noise=0.03, seed=1, threads=2).tobytes()
            os.write(w, b"ok" if got == want else b"differs")
        finally:
            os._exit(0)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        msg = f.read()
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status), f"child died: status {status}"
    assert msg == b"ok"


def _augment_worker(args):
    aug, pts, index = args
    return aug(pts, index).tobytes()


def test_augment_in_fork_pool_equals_in_process(table):
    pts = scan(30000, seed=12)
    aug = murk.Augment(table, "fog", mor=(20, 200), p=0.7, seed=5, range_noise=0.02)
    aug(pts, 0)  # the parent's pool exists before the fork
    want = [aug(pts, i).tobytes() for i in range(8)]
    ctx = mp.get_context("fork")
    with ctx.Pool(2) as pool:
        got = pool.map(_augment_worker, [(aug, pts, i) for i in range(8)], chunksize=1)
    assert got == want


def test_augment_is_a_function_of_seed_and_index(table):
    pts = scan(20000, seed=13)
    aug = murk.Augment(table, "fog", mor=(20, 200), p=0.5, seed=1)
    # Order does not matter.
    fwd = [aug(pts, i).tobytes() for i in range(40)]
    rev = [aug(pts, i).tobytes() for i in reversed(range(40))][::-1]
    assert fwd == rev
    # Each call equals murk.apply with the parameters it says it drew.
    for i in range(40):
        prm = aug.params(i)
        if prm["applied"]:
            ref = murk.apply(pts, table, "fog", mor=prm["mor"], seed=1, key=prm["key"]).tobytes()
            assert fwd[i] == ref
            assert 20 <= prm["mor"] <= 200
        else:
            assert fwd[i] == pts.tobytes()
    # p is honoured (binomial, 2000 draws: 0.5 +- 4.5 sigma)
    applied = np.mean([aug.params(i)["applied"] for i in range(2000)])
    assert abs(applied - 0.5) < 0.05
    # MOR uniform on [20, 200]: mean 110, sd 52; 2000 draws: mean within 4.5 sigma.
    mors = np.array([aug.params(i)["mor"] for i in range(2000)])
    assert abs(mors.mean() - 110) < 4.5 * 52 / np.sqrt(2000)
    # Another seed, other draws.
    other = murk.Augment(table, "fog", mor=(20, 200), p=0.5, seed=2)
    assert [other.params(i) for i in range(10)] != [aug.params(i) for i in range(10)]


def test_augment_pickles_and_checks_early(table):
    aug = murk.Augment(table, "fog", mor=(30, 60), seed=3)
    back = pickle.loads(pickle.dumps(aug))
    pts = scan(5000)
    assert back(pts, 4).tobytes() == aug(pts, 4).tobytes()
    with pytest.raises(murk.TableError, match="snow"):
        murk.Augment(table, "snow", mor=(30, 60))
    with pytest.raises(murk.InputError, match="weather"):
        murk.Augment(table, "hail", mor=(30, 60))
    with pytest.raises(murk.InputError, match="p:"):
        murk.Augment(table, "fog", mor=(30, 60), p=1.5)
    with pytest.raises(murk.InputError, match="mor"):
        murk.Augment(table, "fog", mor=(60, 30))
    with pytest.raises(murk.InputError, match="exactly one"):
        murk.Augment(table, "fog")


def test_thread_setting():
    old = murk.get_num_threads()
    murk.set_num_threads(3)
    assert murk.get_num_threads() == 3
    murk.set_num_threads(0)
    assert murk.get_num_threads() == old
