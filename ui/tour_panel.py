"""The guided step-through of a teaching demo (``voxwarp demo NAME --gui``): a dock with
the step's title and explanation, the demo's figure sheet, and Back / Next; a step
with a scene opens it in the viewport (its deformation model resumes, so the student
can poke it)."""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtGui import QPixmap
from PySide6.QtWidgets import (
    QHBoxLayout,
    QLabel,
    QPushButton,
    QTextBrowser,
    QVBoxLayout,
    QWidget,
)

from voxwarp.teaching.tour import Tour


class TourPanel(QWidget):
    """Steps through a :class:`~voxwarp.teaching.tour.Tour` in a main window.

    Parameters
    ----------
    window
        The main window (``open_path(path)`` opens a step's scene).
    tour
        The tour (:func:`voxwarp.teaching.tour.read_tour`).
    """

    def __init__(self, window: Any, tour: Tour, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._window = window
        self.tour = tour
        self.index = -1
        self.title_label = QLabel()
        self.title_label.setWordWrap(True)
        self.title_label.setTextFormat(Qt.TextFormat.RichText)
        self.counter = QLabel()
        self.text = QTextBrowser()
        self.text.setOpenExternalLinks(False)
        self.figure = QLabel()
        self.figure.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.figure.setMinimumHeight(120)
        self.back_button = QPushButton("◀ Back")
        self.next_button = QPushButton("Next ▶")
        self.back_button.clicked.connect(self.back)
        self.next_button.clicked.connect(self.next)
        buttons = QHBoxLayout()
        buttons.addWidget(self.back_button)
        buttons.addWidget(self.counter, 1, Qt.AlignmentFlag.AlignCenter)
        buttons.addWidget(self.next_button)
        lay = QVBoxLayout(self)
        lay.addWidget(QLabel(f"<b>{tour.title}</b>"))
        lay.addWidget(self.title_label)
        lay.addWidget(self.text, 1)
        lay.addWidget(self.figure)
        lay.addLayout(buttons)
        if tour.figure is not None:
            pix = QPixmap(str(tour.figure))
            if not pix.isNull():
                self.figure.setPixmap(
                    pix.scaledToWidth(280, Qt.TransformationMode.SmoothTransformation)
                )
                self.figure.setToolTip(str(tour.figure))
        self.go(0)

    def go(self, index: int) -> None:
        """Show step ``index`` (0-based); opens its scene if it has one."""
        index = max(0, min(index, len(self.tour.steps) - 1))
        if index == self.index:
            return
        self.index = index
        step = self.tour.steps[index]
        panel = f" (figure panel {step.panel})" if step.panel else ""
        self.title_label.setText(f"<b>{index + 1}. {step.title}</b>{panel}")
        self.text.setPlainText(step.text)
        self.counter.setText(f"{index + 1} / {len(self.tour.steps)}")
        self.back_button.setEnabled(index > 0)
        self.next_button.setEnabled(index < len(self.tour.steps) - 1)
        if step.scene is not None:
            self._window.open_path(step.scene, refit=True)

    def next(self) -> None:
        """The next step."""
        self.go(self.index + 1)

    def back(self) -> None:
        """The previous step."""
        self.go(self.index - 1)
