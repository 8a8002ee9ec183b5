"""Reading and writing: volumes (NIfTI, NRRD, DICOM, TIFF, raw, npz), images (OpenImageIO) and the
bundled samples.
"""
