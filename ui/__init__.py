"""voxwarp desktop GUI (PySide6). Only this package may import Qt."""
