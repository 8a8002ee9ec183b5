"""The napari plugin: reader, sample data and dock widget (``pip install voxwarp[napari]``)."""
