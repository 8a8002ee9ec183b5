"""Qt-free interactive editing: the edit session (pick, drag, undo, save) and keyframes."""
