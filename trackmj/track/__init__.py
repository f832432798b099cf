"""The track physics: the MuJoCo model of one track side and what acts on it.

* :mod:`.mechanics`: the mechanics file (``models/<name>.toml``), validated;
* :mod:`.mjcf`: the generator of the MJCF from it (layout, structure, soft constraints);
* :mod:`.plant`: :class:`~trackmj.track.plant.TrackPlant`, named accessors and the 1 ms step;
* :mod:`.foundation`: the Kelvin–Voigt ground under the pins, a force element;
* :mod:`.energy`: the track's mechanical energy ledger;
* :mod:`.terrain`: ISO 8608 road profiles and heightfields.

Nothing here knows the hydraulics, the controller or a run: the tensioner acts through the
tensioner port (:mod:`trackmj.ports`).
"""
