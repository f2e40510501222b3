"""brdffit._atomic: where outputs land, and what they never replace (issue 32)."""

from __future__ import annotations

import os
import socket
import stat
import threading

import pytest

from brdffit._atomic import (OutputError, atomic_write, check_writable, destination_kind,
                             place)


def _write(path, text: str) -> None:
    with atomic_write(path, "w") as fh:
        fh.write(text)


def test_a_replaced_file_keeps_its_mode_and_a_new_one_gets_the_umask(tmp_path):
    old = tmp_path / "old.json"
    old.write_text("before")
    old.chmod(0o600)
    _write(old, "after")
    assert old.read_text() == "after" and stat.S_IMODE(old.stat().st_mode) == 0o600
    new = tmp_path / "new.json"
    _write(new, "x")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(new.stat().st_mode) == 0o666 & ~umask


def test_a_null_device_is_written_through_and_stays_a_device(null_device):
    before = os.stat(null_device)
    _write(null_device, "discarded")
    after = os.stat(null_device)
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev
    assert stat.S_IMODE(after.st_mode) == stat.S_IMODE(before.st_mode)


def test_a_link_to_a_device_is_written_through_and_a_link_to_a_file_is_replaced(tmp_path,
                                                                                null_device):
    to_null = tmp_path / "sink"
    to_null.symlink_to(null_device)
    _write(to_null, "discarded")
    assert to_null.is_symlink() and stat.S_ISCHR(os.stat(null_device).st_mode)
    target = tmp_path / "target.json"
    target.write_text("kept")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    _write(link, "new")
    assert not link.is_symlink() and link.read_text() == "new" and target.read_text() == "kept"


def test_a_fifo_is_written_through(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    _write(fifo, "through the pipe")
    reader.join(10)
    assert got == ["through the pipe"] and stat.S_ISFIFO(fifo.lstat().st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["pipe"]


def test_directories_and_sockets_are_refused_with_one_line(tmp_path):
    sock_path = tmp_path / "s.sock"
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(sock_path))
        for target, kind in ((tmp_path, "directory"), (sock_path, "socket")):
            assert destination_kind(target) == kind
            for attempt in (lambda: check_writable(target), lambda: _write(target, "x")):
                with pytest.raises(OutputError, match=f"found a {kind}") as info:
                    attempt()
                assert str(target) in str(info.value) and "\n" not in str(info.value)
        tmp = tmp_path / "done.tmp"
        tmp.write_text("x")
        with pytest.raises(OutputError, match="found a socket"):
            place(tmp, sock_path)


def test_the_destination_folder_is_checked_first_and_errors_name_the_users_path(tmp_path):
    with pytest.raises(OutputError, match="found none") as info:
        check_writable(tmp_path / "missing" / "x.npz")
    assert str(tmp_path / "missing" / "x.npz") in str(info.value)
    (tmp_path / "file").write_text("")
    with pytest.raises(OutputError, match="found a regular file"):
        check_writable(tmp_path / "file" / "x.npz")
    with pytest.raises(OutputError) as info:
        check_writable("/proc/x.npz")
    assert str(info.value).startswith("/proc/x.npz: cannot write there") and ".tmp" not in str(info.value)
    assert check_writable(tmp_path / "x.npz") == "new" and list(tmp_path.iterdir()) == [tmp_path / "file"]
