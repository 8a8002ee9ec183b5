"""The dialog that asks which time point or channel of a 4-D/multi-channel file to open.

File › Open of a file holding several volumes meets a
:class:`~voxwarp.io.frames.FrameChoiceError`; :func:`ask_frame` shows the file's shape,
what it holds (with the time step a NIfTI states) and a spin box per axis to choose
along, and returns the ``frame_index=`` / ``channel=`` keywords to open it with.
"""

from __future__ import annotations

from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from voxwarp.io.frames import CHANNEL, FrameChoiceError, frame_text

_LABELS = {"frame_index": "Time point", "channel": "Channel"}


class FrameDialog(QDialog):
    """Choose one volume of a file holding several: a spin box per axis along which
    the file holds more than one (time points, channels)."""

    def __init__(self, parent: QWidget | None, name: str, error: FrameChoiceError) -> None:
        super().__init__(parent)
        self.setWindowTitle(f"Open {name}")
        self.setMinimumWidth(380)
        layout = QVBoxLayout(self)
        shape = " × ".join(str(s) for s in error.shape)
        info = QLabel(f"{name} holds {frame_text(error.axes)} (shape {shape}).\nOpen which one?")
        info.setWordWrap(True)
        layout.addWidget(info)
        form = QFormLayout()
        self.spins: dict[str, QSpinBox] = {}
        for axis in error.axes:
            key = "channel" if axis.kind == CHANNEL else "frame_index"
            if axis.size < 2 or key in self.spins:
                continue
            spin = QSpinBox()
            spin.setRange(0, axis.size - 1)
            spin.setObjectName(key)
            spin.setToolTip(f"0 .. {axis.size - 1}")
            self.spins[key] = spin
            form.addRow(f"{_LABELS[key]} (0–{axis.size - 1}):", spin)
        layout.addLayout(form)
        buttons = QDialogButtonBox(QDialogButtonBox.Ok | QDialogButtonBox.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        layout.addWidget(buttons)

    def choice(self) -> dict[str, int]:
        """The keywords of :func:`voxwarp.io.volumes.load_volume` the spin boxes give."""
        return {key: spin.value() for key, spin in self.spins.items()}


def ask_frame(parent: QWidget | None, name: str, error: FrameChoiceError) -> dict[str, int] | None:
    """Ask which volume of ``name`` to open; ``None`` when cancelled."""
    dialog = FrameDialog(parent, name, error)
    return dialog.choice() if dialog.exec() == QDialog.Accepted else None
