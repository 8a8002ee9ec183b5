"""The napari plugin: reader, sample data and dock widget (``pip install 'voxwarp[napari,gui]'``).

npe2 finds it through ``napari.yaml`` (entry point ``napari.manifest``). Modules:
:mod:`~voxwarp.napari_plugin.convert` (layers <-> volumes, no Qt),
:mod:`~voxwarp.napari_plugin.reader`, :mod:`~voxwarp.napari_plugin.samples`,
:mod:`~voxwarp.napari_plugin.deformed_view` (the headless render, no Qt),
:mod:`~voxwarp.napari_plugin.handoff` (files and process for the voxwarp window, no Qt) and
:mod:`~voxwarp.napari_plugin.widget` (the dock widget, qtpy). See ``docs/napari.md``.
"""
