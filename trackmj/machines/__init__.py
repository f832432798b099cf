"""Machines: a machine is its files (``models/<name>_machine.toml`` naming its mechanics,
hydraulic, control and idler files).

* :mod:`.assembly`: finding a machine (shipped name or file), loading and generating its
  parts;
* :mod:`.default`: the default machine's name (light: the command line's help names it);
* :mod:`.identify`: identifying the equivalent idler on the machine's track;
* :mod:`.idler`: the identified equivalent idler and its file;
* :mod:`.track_plant`: a machine's track as a ``TrackPlant`` (:func:`~.track_plant.load_plant`);
* :mod:`.sizing`: the sizing rules of a machine's tensioner and controller.

A new machine is its files in ``models/``: the shipped ones are found by name there.
"""
