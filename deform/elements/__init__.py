"""Offset field (Knoche 2008 thesis): an element grid moved by a mass-spring model or 3D
ChainMail, each with a CPU reference and a GLSL backend, sampled as an offset-field warp.

Modules: ``grid`` (elements, materials, selections), ``model`` (what both models share:
save/load, drags, the warp), ``massspring``/``spring_model``/``massspring_gpu``,
``chainmail``/``chainmail_model``/``chainmail_cpu``/``chainmail_gpu``, ``gpu_grid`` (the
GPU set-up both GPU solvers use), ``offset_field`` (the warp).
"""
