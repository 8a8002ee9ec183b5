"""PySide6 6.12 loses a reference to None per void Qt call on CPython 3.11; the GUI's
guard (voxwarp.ui.app.guard_none_refcount) keeps a long session from aborting."""

from __future__ import annotations

import os
import subprocess
import sys

SCRIPT = """
import sys
from voxwarp.ui.app import configure_qt
configure_qt()  # installs the guard
from PySide6.QtWidgets import QApplication, QLabel
app = QApplication([])
label = QLabel()
for i in range(50_000):  # far more than None's references in a small process
    label.setText(str(i))
print("done")
"""


def test_many_void_qt_calls_do_not_abort_the_interpreter() -> None:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    res = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=120
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "done"
    assert "none_dealloc" not in res.stderr
