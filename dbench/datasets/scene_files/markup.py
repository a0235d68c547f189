"""A scene file's XML read as Mitsuba's parser reads it, for the walk over the files it
references (:mod:`dbench.datasets.scene_files.assets`; README.md, "Mitsuba scene files").

Mitsuba reads XML with pugixml, which loads files that a strict XML parser refuses. Checked
with ``mi.load_file`` (Mitsuba 3.9.1), it loads and dbench must read:

- bytes that are not UTF-8 where the file declares no other encoding (a Latin-1 ``é`` or
  ``©`` in a comment): pugixml passes them through;
- an ``&`` that begins no character or predefined entity reference (``rock&moss.png``, an
  ``&name;`` no DTD defines): kept as written;
- an attribute given twice: the first counts;
- anything after the root element: ignored.

:func:`root` parses a file with :mod:`xml.etree.ElementTree` and, only where that refuses it,
scans it with those rules; a file neither reads (a tag left open, tags that do not match)
gets the strict parser's message.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET

#: markup that holds no element (comments, CDATA, processing instructions, declarations), or
#: one tag: (closing "/", name, attributes, self-closing "/")
_MARKUP = re.compile(r"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<![^>]*>"
                     r"|<(/?)([A-Za-z_:][\w:.\-]*)((?:[^>\"']|\"[^\"]*\"|'[^']*')*?)(/?)>",
                     re.S)
_ATTRIBUTE = re.compile(r"([^\s=/>]+)\s*=\s*(?:\"([^\"]*)\"|'([^']*)')")
_REFERENCE = re.compile(r"&(lt|gt|amp|quot|apos|#[0-9]+|#x[0-9A-Fa-f]+);")
_PREDEFINED = {"lt": "<", "gt": ">", "amp": "&", "quot": '"', "apos": "'"}
#: byte order marks pugixml reads, longest first (UTF-32 LE begins as UTF-16 LE does)
_BOMS = ((b"\xef\xbb\xbf", "utf-8"), (b"\xff\xfe\x00\x00", "utf-32-le"),
         (b"\x00\x00\xfe\xff", "utf-32-be"), (b"\xff\xfe", "utf-16-le"),
         (b"\xfe\xff", "utf-16-be"))
_LATIN1 = re.compile(rb"\s*<\?xml[^>]*encoding\s*=\s*[\"'](?:latin-?1|iso[-_]?8859-?1)[\"']",
                     re.I)


def root(data: bytes) -> ET.Element:
    """The root element of the XML file whose bytes are ``data`` (module docstring).
    ET.ParseError where neither the strict parser nor the scan reads it."""
    try:
        return ET.fromstring(data)
    except ET.ParseError:
        scanned = _scan(_text(data))
        if scanned is None:
            raise
        return scanned


def _text(data: bytes) -> str:
    for bom, codec in _BOMS:
        if data.startswith(bom):
            return data[len(bom):].decode(codec, "replace")
    # bytes that are not UTF-8 become U+FFFD: a comment is unaffected, and a file name
    # holding them is refused as not found, naming it
    return data.decode("latin-1" if _LATIN1.match(data) else "utf-8", "replace")


def _scan(text: str) -> ET.Element | None:
    """The first element of ``text`` with its descendants; None where a tag is left open or
    closed by another name."""
    stack: list[ET.Element] = []
    for m in _MARKUP.finditer(text):
        closing, name, attributes, empty = m.groups()
        if name is None:
            continue  # a comment, CDATA, a declaration
        if closing:
            if not stack or stack[-1].tag != name:
                return None
            done = stack.pop()
            if not stack:
                return done  # what follows the root element is not read
            continue
        element = ET.Element(name, _attributes(attributes))
        if stack:
            stack[-1].append(element)
        if not empty:
            stack.append(element)
        elif not stack:
            return element
    return None


def _attributes(text: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for m in _ATTRIBUTE.finditer(text):
        value = m.group(2) if m.group(2) is not None else m.group(3)
        out.setdefault(m.group(1), _value(value))  # the first of a repeated name counts
    return out


def _value(raw: str) -> str:
    """An attribute value as pugixml gives it: line ends and tabs as spaces, then references
    replaced (unknown ones kept as written)."""
    raw = re.sub(r"\r\n?|[\n\t]", " ", raw)
    return _REFERENCE.sub(_reference, raw)


def _reference(m: re.Match) -> str:
    name = m.group(1)
    if name in _PREDEFINED:
        return _PREDEFINED[name]
    try:
        return chr(int(name[2:], 16) if name[1] == "x" else int(name[1:]))
    except (ValueError, OverflowError):
        return m.group(0)


__all__ = ["root"]
