"""The workers' warm-up lock (anim/render/warm_lock.py): the first warm-up of
a kernel set on a machine runs alone, later ones at once."""
import fcntl
import threading
import time

import pytest

from anim.render.warm_lock import warm_once


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FRUSTRACE_CACHE_DIR", str(tmp_path))
    return tmp_path


def _timed(spans, name, seconds=0.3):
    def warm():
        t0 = time.monotonic()
        time.sleep(seconds)
        spans[name] = (t0, time.monotonic())
        return name
    return warm


def test_the_first_warm_up_of_a_set_runs_alone_and_later_ones_at_once(cache):
    spans, results = {}, {}

    def run(name, delay):
        time.sleep(delay)
        results[name] = warm_once("scene A", _timed(spans, name))
    threads = [threading.Thread(target=run, args=("first", 0.0)), threading.Thread(target=run, args=("second", 0.1))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert results == {"first": "first", "second": "second"}
    # one waited for the other, whichever took the lock first on a loaded host
    (_, end_a), (start_b, _) = sorted(spans.values())
    assert start_b >= end_a
    # the set is marked warm: with the lock held elsewhere, a warm-up of it
    # goes on (without the marker it would wait for the lock: for ever here)
    with open(cache / "warm" / "warm-up.lock", "a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        third = []
        warm = threading.Thread(target=lambda: third.append(warm_once("scene A", _timed(spans, "third", 0.0))))
        warm.start()
        warm.join(30)
        assert third == ["third"]
        # another set waits for the lock
        done = []
        other = threading.Thread(target=lambda: done.append(warm_once("scene B", _timed(spans, "B", 0.0))))
        other.start()
        other.join(0.3)
        assert not done
        fcntl.flock(held, fcntl.LOCK_UN)
        other.join(5)
        assert done == ["B"]


def test_a_failed_warm_up_leaves_no_marker_and_no_lock(cache):
    def fail():
        raise RuntimeError("out of memory")
    with pytest.raises(RuntimeError):
        warm_once("scene C", fail)
    assert list((cache / "warm").glob("*.done")) == []
    spans = {}
    assert warm_once("scene C", _timed(spans, "again", 0.0)) == "again"   # the lock is free
    assert len(list((cache / "warm").glob("*.done"))) == 1


def test_without_a_cache_directory_every_warm_up_runs_at_once(monkeypatch):
    monkeypatch.setenv("FRUSTRACE_CACHE_DIR", "")
    assert warm_once("scene D", lambda: 7) == 7
