"""Names of the generated track's bodies and pin connects, one rule for the generator, the
plant and the playback."""


def link_name(k: int) -> str:
    """Name of link k (body; its joints add ``_x``, ``_z``, ``_pitch``, geoms ``_rail``,
    ``_pin``, ``_shoe``): ``link_00`` .. ``link_99``, ``link_100`` .. for any count."""
    return f"link_{k:02d}"


def stretch_name(k: int) -> str:
    """Name of the slide that carries pin k's own compliance (structure "slides"):
    ``link_kk_stretch``, a joint of link k."""
    return link_name(k) + "_stretch"


def pin_name(k: int) -> str:
    """Name of pin k, the connect joining link k−1 and link k (``pin_00`` ..)."""
    return f"pin_{k:02d}"
