"""The read cache (`woundsweep.store.readcache`): a warm read gives exactly the cold read's
rows and states, changed, damaged and deleted result files are read again, a damaged cache
is ignored and rebuilt, and racing writers never leave a damaged cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pandas as pd
import pytest
from store_files import manifest, outcome, store_converged

from woundsweep.core.errors import StoreError
from woundsweep.store import readcache
from woundsweep.store.readcache import READ_CACHE_NAME, ReadCache, _load
from woundsweep.store.reader import read_checked, read_results, scan_results, scan_store
from woundsweep.store.writer import Store

JOBS = 5


def _stored(rd: Path) -> list[Path]:
    """Jobs 0-4 stored (job 4 failed), their result files in job order."""
    for i in range(JOBS - 1):
        store_converged(rd, i)
    job = manifest(rd).iloc[JOBS - 1].to_dict()
    Store(rd).write_job(job, outcome("invalid"), (1, 6), "none", "0/1")
    return [Store(rd).result_path(manifest(rd)["job_id"].iloc[i]) for i in range(JOBS)]


def _states(rd: Path, use_cache: bool = True) -> tuple[dict[str, str], pd.DataFrame]:
    scan = scan_store(rd, use_cache=use_cache)
    return {j: str(c.state) for j, c in scan.checks.items()}, scan_results(scan)


def _no_file_reads(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(path: Path, job_id: str | None) -> None:
        raise AssertionError(f"{path} read although the cache holds it")

    monkeypatch.setattr(readcache, "read_checked", refuse)


def test_warm_read_equals_cold_read_and_opens_no_result_file(
    empty_run: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    paths = _stored(empty_run)
    fields = empty_run / "fields" / f"{manifest(empty_run)['job_id'].iloc[1]}.h5"
    fields.write_bytes(fields.read_bytes()[:500])  # job 1 damaged (its fields file)
    cold_states, cold_rows = _states(empty_run, use_cache=False)
    assert sorted(cold_states.values()).count("damaged") == 1
    assert (empty_run / READ_CACHE_NAME).is_file()  # the verifying read wrote the cache
    _no_file_reads(monkeypatch)
    warm_states, warm_rows = _states(empty_run)
    assert warm_states == cold_states
    pd.testing.assert_frame_equal(warm_rows, cold_rows)
    assert len(warm_rows) == 6 * (JOBS - 1)  # the damaged job's rows are not done
    fields.unlink()  # damage to a fields file is seen through the cache
    with pytest.raises(StoreError, match="missing or truncated"):
        read_results(empty_run)
    monkeypatch.undo()
    paths[1].unlink()
    cold = read_results(empty_run)
    _no_file_reads(monkeypatch)
    pd.testing.assert_frame_equal(read_results(empty_run), cold)


def test_a_rewritten_result_is_read_again(empty_run: Path) -> None:
    paths = _stored(empty_run)
    assert set(read_results(empty_run)["failure_class"]) == {"converged", "invalid"}
    job = manifest(empty_run).iloc[0].to_dict()
    Store(empty_run).write_job(job, outcome("invalid"), (1, 6), "none", "0/1")
    rows = read_results(empty_run)
    assert rows.loc[rows["job_id"] == job["job_id"], "failure_class"].unique().tolist() == [
        "invalid"
    ]
    pd.testing.assert_frame_equal(rows, _cold_read(empty_run))
    assert paths[0].is_file()


def _cold_read(rd: Path) -> pd.DataFrame:
    (rd / READ_CACHE_NAME).unlink(missing_ok=True)
    return read_results(rd)


@pytest.mark.parametrize("damage", ["truncated", "same-size, mtime put back"])
def test_a_result_damaged_after_it_was_cached_is_corrupt(empty_run: Path, damage: str) -> None:
    paths = _stored(empty_run)
    read_results(empty_run)  # cached
    victim = paths[2]
    st = victim.stat()
    data = bytearray(victim.read_bytes())
    if damage == "truncated":
        victim.write_bytes(bytes(data[:-30]))
    else:
        victim.write_bytes(_detected_flip(victim, bytes(data)))
        os.utime(victim, ns=(st.st_atime_ns, st.st_mtime_ns))  # size and mtime as cached
        assert victim.stat().st_mtime_ns == st.st_mtime_ns
    with pytest.raises(StoreError, match="corrupt result file") as err:
        read_results(empty_run)
    assert str(victim) in str(err.value)
    states, _ = _states(empty_run)
    assert states == _states(empty_run, use_cache=False)[0]
    assert states[manifest(empty_run)["job_id"].iloc[2]] == "corrupt"


def _detected_flip(path: Path, data: bytes) -> bytes:
    """``data`` (the bytes of result file ``path``) with one byte flipped where a full read
    finds it (some bytes, such as padding, no check covers)."""
    for off in range(4, len(data)):
        bad = data[:off] + bytes([data[off] ^ 0xFF]) + data[off + 1 :]
        path.write_bytes(bad)
        try:
            read_checked(path, None)
        except StoreError:
            return bad
    raise AssertionError("no detected flip")


def test_what_the_cache_trusts_and_status_verify(
    empty_run: Path, monkeypatch: pytest.MonkeyPatch, run_main
) -> None:
    """On a filesystem whose ctime and inode said nothing, a file changed in place with its
    size and mtime put back would come from the cache: `status --verify` reads it."""
    monkeypatch.setattr(readcache, "_key", _size_mtime)
    monkeypatch.setattr(readcache, "read_checked", _size_mtime_keyed(readcache.read_checked))
    paths = _stored(empty_run)
    read_results(empty_run)
    victim = paths[0]
    st = victim.stat()
    victim.write_bytes(_detected_flip(victim, victim.read_bytes()))
    os.utime(victim, ns=(st.st_atime_ns, st.st_mtime_ns))
    code, out, _ = run_main("status", empty_run, "--json")
    assert code == 0 and json.loads(out)["jobs_damaged"] == 0  # trusted: the cache's rows
    code, out, _ = run_main("status", empty_run, "--json", "--verify")
    assert code == 0 and json.loads(out)["jobs_damaged"] == 1
    assert str(victim) in json.loads(out)["damaged_example"]
    code, out, _ = run_main("status", empty_run, "--json")  # --verify wrote the cache anew
    assert code == 0 and json.loads(out)["jobs_damaged"] == 1


def _size_mtime(path: Path) -> tuple[int, ...]:
    st = path.stat()
    return (st.st_size, st.st_mtime_ns)


def _size_mtime_keyed(read):  # type: ignore[no-untyped-def]
    def wrapped(path: Path, job_id: str | None):  # type: ignore[no-untyped-def]
        meta, table, _ = read(path, job_id)
        return meta, table, _size_mtime(path)

    return wrapped


def test_a_deleted_result_disappears(empty_run: Path) -> None:
    paths = _stored(empty_run)
    jid = manifest(empty_run)["job_id"].iloc[3]
    assert jid in set(read_results(empty_run)["job_id"])
    paths[3].unlink()
    assert jid not in set(read_results(empty_run)["job_id"])
    assert jid not in scan_store(empty_run).checks
    assert "job-" + jid + ".parquet" not in _load(empty_run / READ_CACHE_NAME)[1]


@pytest.mark.parametrize(
    "damage", ["garbage", "bit flip", "truncated", "other format", "directory", "fifo", "empty"]
)
def test_a_damaged_cache_is_ignored_and_rebuilt(empty_run: Path, damage: str) -> None:
    _stored(empty_run)
    cold_states, cold_rows = _states(empty_run, use_cache=False)
    cache = empty_run / READ_CACHE_NAME
    data = cache.read_bytes()
    cache.unlink()
    if damage == "garbage":
        cache.write_bytes(os.urandom(len(data)))
    elif damage == "bit flip":
        cache.write_bytes(data[:-100] + bytes([data[-100] ^ 1]) + data[-99:])
    elif damage == "truncated":
        cache.write_bytes(data[: len(data) // 2])
    elif damage == "other format":
        cache.write_bytes(data.replace(b"read cache 1", b"read cache 0", 1))
    elif damage == "directory":
        cache.mkdir()
    elif damage == "fifo":
        os.mkfifo(cache)
    else:
        cache.write_bytes(b"")
    assert _load(cache) == (None, {})
    states, rows = _states(empty_run)
    assert states == cold_states
    pd.testing.assert_frame_equal(rows, cold_rows)
    if damage not in ("directory", "fifo"):  # replaced by a whole cache of every file
        assert len(_load(cache)[1]) == JOBS


def test_racing_writers_and_readers_leave_a_whole_cache(empty_run: Path) -> None:
    _stored(empty_run)
    writer = subprocess.Popen(
        [sys.executable, "-c", _WRITER, str(empty_run)],
        cwd=Path(__file__).parent.parent / "support",
    )
    errors: list[BaseException] = []

    def read() -> None:
        while writer.poll() is None:
            try:
                scan_store(empty_run)
                read_results(empty_run)
            except BaseException as err:  # noqa: BLE001 - reported below
                errors.append(err)
                return

    readers = [threading.Thread(target=read) for _ in range(2)]
    for t in readers:
        t.start()
    assert writer.wait(timeout=300) == 0
    for t in readers:
        t.join()
    assert not errors, errors
    table, entries = _load(empty_run / READ_CACHE_NAME)
    assert table is not None and entries  # whole, whichever reader wrote it last
    warm = read_results(empty_run)
    pd.testing.assert_frame_equal(warm, _cold_read(empty_run))
    assert warm["job_id"].nunique() == JOBS + 8
    assert ReadCache(empty_run).path.is_file()


_WRITER = """
import sys
from pathlib import Path
from store_files import manifest, outcome
from woundsweep.store.writer import Store
rd = Path(sys.argv[1])
store = Store(rd)
for rnd in range(3):
    for i in range(5, 13):
        job = manifest(rd).iloc[i].to_dict()
        cls = ("invalid", "not-converged", "invalid")[rnd]
        store.write_job(job, outcome(cls), (1, 6), "none", "0/1")
"""
