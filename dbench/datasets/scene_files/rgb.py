"""Spectral and polarized scene files in the RGB variant dbench renders in: what is converted,
what is refused (README.md, "Mitsuba scene files").

dbench renders in Mitsuba's RGB variants (``llvm_ad_rgb``, ``scalar_rgb``). A file written for
a spectral or polarized variant either loads there with a conversion, which the record of the
render states, or is refused before anything is created, naming the construct and where it is
(one line, exit 2). Checked with Mitsuba 3.9.1 in ``llvm_ad_rgb``:

- a ``<spectrum>`` given as wavelength:value pairs or read from a file is converted to RGB by
  Mitsuba's parser (stated);
- ``<spectrum type="d65">`` is RGB white (1, 1, 1) (stated);
- ``<spectrum type="blackbody">``, ``"regular"`` and ``"irregular"`` load but fail at the first
  render ("Not implemented for non-spectral modes"), and while one exists every other render of
  the process fails too: refused before the scene is created;
- the polarizing BSDFs ``pplastic``, ``polarizer``, ``retarder`` and ``circular`` render
  without polarization (stated); ``measured_polarized`` is refused by Mitsuba itself;
- ``<integrator type="stokes">`` is unwrapped (:mod:`dbench.datasets.scene_files.integrator`).
"""
from __future__ import annotations

from ...errors import DbenchInputError
from ..mitsuba_env import mitsuba
from .xml import where

#: spectrum plugins with no RGB form (module docstring)
SPECTRAL_ONLY = ("blackbody", "regular", "irregular")
#: BSDFs whose polarization the RGB variant drops
POLARIZING = ("pplastic", "polarizer", "retarder", "circular")


def rgb_notes(state, path: str) -> tuple[str, ...]:
    """The conversions of the file whose parser state is ``state`` to the RGB variant, one line
    each (empty: none). DbenchInputError naming the first construct that has no RGB form."""
    mi = mitsuba()
    spectra = 0
    d65 = 0
    polarizing: dict[str, int] = {}
    for node in state.nodes:
        plugin = node.props.plugin_name()
        if node.type == mi.ObjectType.Texture and plugin in SPECTRAL_ONLY:
            raise DbenchInputError(f"--scene {path}: <spectrum type=\"{plugin}\"> "
                                   f"at {where(state, node)} has no RGB form in Mitsuba's RGB "
                                   f"variant, which dbench renders in; give the colour as <rgb>")
        if node.type == mi.ObjectType.Texture and plugin == "d65":
            d65 += 1
        if node.type == mi.ObjectType.BSDF and plugin in POLARIZING:
            polarizing[plugin] = polarizing.get(plugin, 0) + 1
        for key in node.props.keys():
            if node.props.type(key) == mi.Properties.Type.Spectrum \
                    and not node.props.get(key).is_uniform():
                spectra += 1
    notes = []
    if spectra:
        notes.append(f"{spectra} spectrum value(s) given per wavelength converted to RGB by "
                     f"Mitsuba's parser (RGB variant)")
    if d65:
        notes.append(f"{d65} d65 spectrum(s) rendered as RGB white (1, 1, 1) (RGB variant)")
    if polarizing:
        names = ", ".join(f"{k} ×{v}" for k, v in sorted(polarizing.items()))
        notes.append(f"polarizing BSDFs ({names}) rendered without polarization (RGB variant)")
    return tuple(notes)


__all__ = ["rgb_notes", "SPECTRAL_ONLY", "POLARIZING"]
