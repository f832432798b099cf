"""Tensioner elements: what pushes the idler carrier, each on the element port
(``ports.Element``) with the builder its registry line calls
(:data:`trackmj.sim.registry.ELEMENTS`, ``build(ElementContext) -> Element``).

* :mod:`.hydraulic`: the hydraulic plugin (:mod:`trackmj.hydraulics`), tp, tp-weak, dp-a;
* :mod:`.ideal`: dp-b's ideal force source;
* :mod:`.passive`: a preload spring-damper (a tensioner file's ``[passive]``);
* :mod:`.fmu`: an FMU (a tensioner file's ``[fmu]``);
* :mod:`.prescribed`: bare prescribed-force elements for settling, identification, replay;
* :mod:`.tensioner_file`: the tensioner files that choose an element in place of the
  hydraulic plugin; :mod:`.context`: what a builder gets; :mod:`.cylinder`: the lumped
  cylinder; :mod:`.energy_table`: the hydraulic run's energy table.

A new element is its own module here with a ``build(context)`` function, and one line in
:data:`trackmj.sim.registry.ELEMENTS`.
"""
