"""Generator of a machine's track-side MuJoCo model (``models/lf1352.xml`` and its scene
``models/lf1352_scene.xml`` for the study's LF1352; any single-side layout).

Modules, each a stage of the model: :mod:`.layout` (pin positions that close the loop and
the checks that refuse a layout that cannot close), :mod:`.geometry` (derived geometry:
wraps, spans, static strand tension), :mod:`.soft` (stated stiffness and damping -> MuJoCo
soft-constraint parameters), :mod:`.names` (body, joint and geom names),
:mod:`.structure` (short hinged chains), :mod:`.builders` (one builder per subtree, the
machine/scene split, the heightfield terrain), :mod:`.generate` (settled ``home``
keyframe, the committed files), :mod:`.cache` (generated models by content hash),
:mod:`.tree` (find-or-raise access to the element tree). The
parameters they read are the mechanics file's (:mod:`trackmj.track.mechanics`). Nothing
here imports the plant.
"""
