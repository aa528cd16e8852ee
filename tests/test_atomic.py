"""Tests of flowchart2sdnn.atomic: all-or-nothing replacement, cleanup, output-path checks, SIGKILL mid-write."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import flowchart2sdnn
from flowchart2sdnn.atomic import (
    TEMP_PREFIX,
    atomic_open,
    atomic_write_bytes,
    atomic_write_text,
    check_output_path,
    clean_temp_files,
)
from flowchart2sdnn.errors import SdnnError

ROOT = Path(flowchart2sdnn.__file__).resolve().parents[1]


def test_write_bytes_and_text(tmp_path):
    target = tmp_path / "out.bin"
    atomic_write_bytes(target, b"\x00\x01abc")
    assert target.read_bytes() == b"\x00\x01abc"
    atomic_write_text(target, "line\nzwei \u00fc\r\n")
    assert target.read_bytes() == "line\nzwei \u00fc\r\n".encode()  # no newline translation
    atomic_write_text(str(target), "\u00fc", encoding="latin-1")
    assert target.read_bytes() == b"\xfc"
    assert os.listdir(tmp_path) == ["out.bin"]


def test_atomic_open_text_and_binary(tmp_path):
    target = tmp_path / "a.txt"
    with atomic_open(target) as handle:
        handle.write("x")
        assert not target.exists()  # nothing visible before the block ends
        assert [p.name for p in tmp_path.iterdir()][0].startswith(TEMP_PREFIX + "a.txt.")
    assert target.read_text() == "x"
    with atomic_open(target, "wb") as handle:
        handle.write(b"yz")
    assert target.read_bytes() == b"yz"
    assert os.listdir(tmp_path) == ["a.txt"]


@pytest.mark.parametrize("error", [RuntimeError("boom"), KeyboardInterrupt()])
def test_exception_keeps_old_file_and_removes_temp(tmp_path, error):
    target = tmp_path / "keep.csv"
    target.write_bytes(b"old content\n")
    with pytest.raises(type(error)):
        with atomic_open(target) as handle:
            handle.write("new, half written" * 1000)
            handle.flush()
            raise error
    assert target.read_bytes() == b"old content\n"
    assert os.listdir(tmp_path) == ["keep.csv"]


def test_exception_creates_nothing_when_target_is_new(tmp_path):
    with pytest.raises(ValueError):
        with atomic_open(tmp_path / "new.csv") as handle:
            handle.write("partial")
            raise ValueError
    assert os.listdir(tmp_path) == []


def test_bad_mode_and_missing_directory(tmp_path):
    with pytest.raises(ValueError):
        with atomic_open(tmp_path / "x", "a"):
            pass
    with pytest.raises(FileNotFoundError):
        atomic_write_bytes(tmp_path / "no" / "x", b"1")
    assert os.listdir(tmp_path) == []


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_permissions(tmp_path):
    target = tmp_path / "mode.txt"
    target.write_text("old")
    target.chmod(0o640)
    atomic_write_text(target, "new")
    assert (target.stat().st_mode & 0o777) == 0o640
    plain = tmp_path / "plain.txt"
    plain.write_text("x")  # what the umask gives an ordinary new file
    fresh = tmp_path / "fresh.txt"
    atomic_write_text(fresh, "x")
    assert (fresh.stat().st_mode & 0o777) == (plain.stat().st_mode & 0o777)


@pytest.mark.skipif(os.name != "posix", reason="symlinks")
def test_symlink_is_followed(tmp_path):
    real = tmp_path / "real.csv"
    real.write_text("old")
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    atomic_write_text(link, "new")
    assert link.is_symlink() and real.read_text() == "new"


def test_clean_temp_files_removes_only_its_own(tmp_path):
    target = tmp_path / "out[1].csv"
    target.write_text("x")
    mine = [tmp_path / f"{TEMP_PREFIX}out[1].csv.0123abcd", tmp_path / f"{TEMP_PREFIX}out[1].csv.ffffffff"]
    others = [tmp_path / f"{TEMP_PREFIX}other.csv.0123abcd", tmp_path / f"{TEMP_PREFIX}out[1].csv.notahex!",
              tmp_path / "out[1].csv.bak", tmp_path / f"{TEMP_PREFIX}out[1].csv.0123abcd0"]
    for p in mine + others:
        p.write_text("t")
    assert clean_temp_files(target) == sorted(mine)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in [target, *others])


# ---------------------------------------------------------------- check_output_path


def _code(call) -> str:
    with pytest.raises(SdnnError) as info:
        call()
    return info.value.diagnostics[0].code


def test_check_output_path(tmp_path, monkeypatch):
    data = tmp_path / "data.csv"
    data.write_text("a\n1\n")
    out = tmp_path / "result.csv"
    check_output_path(out, [data], force=False)  # new file: fine
    out.write_text("x")
    check_output_path(out, [data])  # exists, force: fine
    assert _code(lambda: check_output_path(out, [data], force=False)) == "OUT003"
    assert _code(lambda: check_output_path(tmp_path / "missing" / "r.csv")) == "OUT001"
    assert _code(lambda: check_output_path(tmp_path)) == "OUT004"
    assert _code(lambda: check_output_path(data, [out, data])) == "OUT002"
    monkeypatch.chdir(tmp_path)
    assert _code(lambda: check_output_path("data.csv", [str(data)])) == "OUT002"
    assert _code(lambda: check_output_path(Path("sub/../data.csv"), ["./data.csv"])) == "OUT001"  # no sub/
    (tmp_path / "sub").mkdir()
    assert _code(lambda: check_output_path(Path("sub/../data.csv"), ["./data.csv"])) == "OUT002"
    # an input that does not exist yet is compared by resolved path
    assert _code(lambda: check_output_path("later.csv", [tmp_path / "later.csv"])) == "OUT002"
    with pytest.raises(SdnnError, match="would overwrite its input"):
        check_output_path(data, [data])


@pytest.mark.skipif(os.name != "posix", reason="links")
def test_check_output_path_through_links(tmp_path):
    data = tmp_path / "data.csv"
    data.write_text("a\n1\n")
    hard = tmp_path / "hard.csv"
    os.link(data, hard)
    soft = tmp_path / "soft.csv"
    soft.symlink_to(data)
    assert _code(lambda: check_output_path(hard, [data])) == "OUT002"
    assert _code(lambda: check_output_path(soft, [data])) == "OUT002"
    assert _code(lambda: check_output_path(data, [soft])) == "OUT002"


# ---------------------------------------------------------------- SIGKILL in the middle of writes

SIZE = 50 * 2**20

CHILD = """
import sys
from flowchart2sdnn.atomic import atomic_write_bytes
target, size = sys.argv[1], int(sys.argv[2])
def content(k):
    return bytes((i * 7 + k) % 256 for i in range(256)) * (size // 256)
versions = [content(1), content(2)]
atomic_write_bytes(target, versions[0])
print("ready", flush=True)
k = 1
while True:
    atomic_write_bytes(target, versions[k % 2])
    k += 1
"""


def _content(k: int, size: int) -> bytes:
    return bytes((i * 7 + k) % 256 for i in range(256)) * (size // 256)


def _start(target: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(target), str(SIZE)], stdout=subprocess.PIPE,
                             env=env, cwd=ROOT)
    assert child.stdout.readline() == b"ready\n"  # the first write is complete; now kill at any moment
    return child


@pytest.mark.skipif(os.name != "posix", reason="SIGKILL")
def test_sigkill_never_leaves_a_partial_file(tmp_path):
    target = tmp_path / "big.bin"
    target.write_bytes(_content(0, SIZE))
    complete = {hashlib.sha256(_content(k, SIZE)).hexdigest(): k for k in (1, 2)}
    rng = np.random.default_rng(20240611)
    killed_mid_write = 0
    for trial in range(6):
        child = _start(target)
        try:
            if trial == 0:
                # deterministic: wait for a temp file with some bytes in it, then kill at once
                deadline = time.monotonic() + 5
                while time.monotonic() < deadline:
                    temps = [p for p in tmp_path.iterdir() if p.name.startswith(TEMP_PREFIX)]
                    if any(0 < p.stat().st_size < SIZE for p in temps if p.exists()):
                        break
            else:
                time.sleep(float(rng.uniform(0.0, 0.35)))
        finally:
            child.send_signal(signal.SIGKILL)
            child.wait(timeout=10)
            child.stdout.close()
        assert child.returncode == -signal.SIGKILL
        digest = hashlib.sha256(target.read_bytes()).hexdigest()
        assert digest in complete, f"trial {trial}: target is neither complete version"
        strays = [p for p in tmp_path.iterdir() if p != target]
        # documented: only temp files named TEMP_PREFIX + target name + '.' + 8 hex digits may remain
        assert all(p.name.startswith(f"{TEMP_PREFIX}{target.name}.") for p in strays), strays
        killed_mid_write += bool(strays)
        assert clean_temp_files(target) == sorted(strays)
        assert os.listdir(tmp_path) == [target.name]
    assert killed_mid_write >= 1  # at least one kill really hit a write in progress
