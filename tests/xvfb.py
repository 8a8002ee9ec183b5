"""Start a private Xvfb display (``-displayfd`` picks a free number), for the GUI tests
(tests/ui/conftest.py) and the napari child processes (tests/napari/xvfb.py)."""

from __future__ import annotations

import os
import subprocess


def start_xvfb(screen: str) -> tuple[subprocess.Popen[bytes], str]:
    """Start ``Xvfb`` with one ``screen`` (``"WxHxD"``); returns the process and its
    display number as a string, empty when Xvfb reported none (the caller kills it)."""
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", screen, "-nolisten", "tcp"],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    with os.fdopen(read_fd) as f:
        return proc, f.readline().strip()
