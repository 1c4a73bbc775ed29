"""murk.fit_partial / FitState: map and merge give murk fit's bytes."""

from __future__ import annotations

import pickle
import random
import subprocess

import pytest

import murk
from conftest import CAMPAIGN


def _merge_randomly(states, rng):
    states = list(states)
    while len(states) > 1:
        rng.shuffle(states)
        a, b = states.pop(), states.pop()
        states.append(a.merge(b))
    return states[0]


@pytest.mark.parametrize("n", [1, 3])
def test_partial_states_merge_to_the_cli_table(fitted, n):
    rng = random.Random(n)
    clear = [murk.fit_partial(CAMPAIGN, shard=(k, n), bootstrap=20) for k in range(1, n + 1)]
    # States travel by pickle (what Ray and multiprocessing do).
    clear = [pickle.loads(pickle.dumps(s)) for s in clear]
    ref = _merge_randomly(clear, rng)
    degraded = [murk.fit_partial(CAMPAIGN, shard=(k, n), reference=ref, bootstrap=20)
                for k in range(1, n + 1)]
    whole = _merge_randomly(clear + degraded, rng)
    assert whole.complete and whole.missing is None
    assert whole.finish().to_json() == fitted.read_text()


def test_incomplete_and_mismatched_states_raise(tmp_path):
    a = murk.fit_partial(CAMPAIGN, shard=(1, 2), bootstrap=20)
    with pytest.raises(murk.FitError, match="clear recordings not mapped"):
        a.finish()
    b = murk.fit_partial(CAMPAIGN, shard=(2, 2), bootstrap=21)
    with pytest.raises(murk.FitError, match="bootstrap_replicates = 20 vs 21"):
        a.merge(b)
    with pytest.raises(murk.FitError, match="a reference needs every clear recording"):
        murk.fit_partial(CAMPAIGN, reference=a, bootstrap=20)
    with pytest.raises(murk.InputError, match="shard"):
        murk.fit_partial(CAMPAIGN, shard=(3, 2))
    p = tmp_path / "a.state"
    a.write(p)
    p.write_bytes(p.read_bytes()[:-10])
    with pytest.raises(murk.FitError, match="a.state: truncated"):
        murk.FitState.read(p)


def test_cli_merge_of_python_states(tmp_path, cli, fitted):
    ref = murk.fit_partial(CAMPAIGN, bootstrap=20)
    ref.write(tmp_path / "clear.state")
    half = murk.fit_partial(CAMPAIGN, shard=(1, 2), reference=ref, bootstrap=20)
    half.write(tmp_path / "d1.state")
    subprocess.run([str(cli), "fit", str(CAMPAIGN), "--partial", str(tmp_path / "d2.state"), "--shard", "2/2",
                    "--reference", str(tmp_path / "clear.state"), "--bootstrap", "20"],
                   check=True, capture_output=True)
    p = subprocess.run([str(cli), "fit", "--merge", str(tmp_path / "clear.state"), str(tmp_path / "d1.state"),
                        "--out", str(tmp_path / "t.json")], capture_output=True, text=True)
    assert p.returncode != 0 and "degraded recordings not mapped" in p.stderr
    subprocess.run([str(cli), "fit", "--merge", str(tmp_path / "d2.state"), str(tmp_path / "clear.state"),
                    str(tmp_path / "d1.state"), "--out", str(tmp_path / "t.json")],
                   check=True, capture_output=True)
    assert (tmp_path / "t.json").read_text() == fitted.read_text()


def test_spilled_clear_images_give_the_cli_table(tmp_path, cli, fitted):
    """``set_clear_memory(0)`` spills every clear image to a file in
    ``spill_dir``: the same table bytes, nothing left in the folder; a
    negative budget raises the CLI's message."""
    try:
        murk.set_clear_memory(0, spill_dir=tmp_path)
        t = murk.fit(CAMPAIGN, bootstrap=20)
        assert t.to_json() == fitted.read_text()
        assert list(tmp_path.iterdir()) == []
        with pytest.raises(murk.InputError, match="clear_memory_mb") as e:
            murk.set_clear_memory(-1)
        r = subprocess.run([str(cli), "fit", str(CAMPAIGN), "--out", str(tmp_path / "t.json"),
                            "--clear-memory-mb=-1"], capture_output=True, text=True)
        assert r.returncode != 0 and str(e.value) in r.stderr, r.stderr
        with pytest.raises(murk.FitError, match="no-such-folder"):
            murk.set_clear_memory(0, spill_dir=tmp_path / "no-such-folder")
            murk.fit(CAMPAIGN, bootstrap=20)
    finally:
        murk.set_clear_memory(256)
