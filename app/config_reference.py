"""The configuration reference: every key of every section with its default and meaning, taken from
the code's own tables, so that the documentation cannot drift from it.

Descriptions of the [filter], [detector], [tof] and [profiles.NAME] keys are the numpydoc
``Attributes`` entries of the dataclasses they map onto (``NavConfig``, ``DetectorParams``,
``TofConfig``, ``UnitProfile``); the [session], [unit] and [calibration] keys are described in
:data:`SESSION_KEYS`. ``docs/generate.py`` writes :func:`markdown_table` into the documentation.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
from dataclasses import dataclass
from typing import Any

from footnav.app.config import defaults, toml_value
from footnav.pipeline.aiding.tof_types import TofConfig
from footnav.pipeline.navigation.navigator import NavConfig
from footnav.pipeline.navigation.profiles import UnitProfile
from footnav.pipeline.stance.detectors import DetectorParams

SESSION_KEYS: dict[str, str] = {
    "session.sessions_dir": "folder that capture files are written to",
    "session.capture": "capture every byte of every live session and demo (replayable later)",
    "session.capture_flush_s": "captured bytes reach the operating system at most this late (what a crash can lose), s",
    "unit.profile": "the unit's noise profile: a built-in one or one of [profiles.NAME]",
    "unit.rate_divider": "output every 2**K samples of the unit's base rate, K = 0..14 (footnav navigates at the "
    "rate the unit's clock gives)",
    "calibration.dir": "folder of calibration files (empty: $FOOTNAV_CALIBRATION_DIR, else "
    "$XDG_CONFIG_HOME/footnav/calibration, else ~/.config/footnav/calibration)",
    "calibration.apply": "apply a unit's calibration file when it connects or its capture is replayed",
}
"""Meaning of the keys that map onto no settings dataclass."""

_SECTION_CLASS: dict[str, type] = {"filter": NavConfig, "detector": DetectorParams, "tof": TofConfig}
_ENTRY = re.compile(r"^(?P<names>[A-Za-z_][\w, ]*)$")


@dataclass(frozen=True, slots=True)
class ReferenceRow:
    """One configuration key: ``section.key``, its default, and what it means (with its unit)."""

    key: str
    default: Any
    description: str


def attribute_docs(cls: type) -> dict[str, str]:
    """The numpydoc ``Attributes`` entries of ``cls``'s docstring, one per attribute name (an entry
    naming several attributes, ``a, b``, describes each of them)."""
    lines = (inspect.getdoc(cls) or "").splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == "Attributes") + 2
    except StopIteration:
        return {}
    docs: dict[str, str] = {}
    names: list[str] = []
    text: list[str] = []

    def flush() -> None:
        for name in names:
            docs[name] = " ".join(text).strip()

    body = lines[start:]
    for i, line in enumerate(body):
        if line and not line.startswith(" "):
            match = _ENTRY.match(line)
            if match is None or (i + 1 < len(body) and body[i + 1].startswith("---")):
                break  # the next section
            flush()
            names, text = [n.strip() for n in match["names"].split(",")], []
        elif line.strip():
            text.append(line.strip())
    flush()
    return docs


def rows() -> list[ReferenceRow]:
    """Every key of the configuration file in file order, then the fields of a ``[profiles.NAME]``
    table (shown with the default profile's values)."""
    cfg = defaults()
    docs = {section: attribute_docs(cls) for section, cls in _SECTION_CLASS.items()}
    out = []
    for key, setting in cfg.values.items():
        section, _, name = key.partition(".")
        description = SESSION_KEYS.get(key) or docs.get(section, {}).get(name, "")
        out.append(ReferenceRow(key, setting.value, description))
    profile = cfg.profile()
    profile_docs = attribute_docs(UnitProfile)
    out.append(
        ReferenceRow("profiles.NAME.base", "generic", "the built-in profile a [profiles.NAME] table starts from")
    )
    for field in dataclasses.fields(UnitProfile):
        if field.name != "name":
            out.append(
                ReferenceRow(f"profiles.NAME.{field.name}", getattr(profile, field.name), profile_docs[field.name])
            )
    return out


_ROLE = re.compile(r":\w+:`~?([^`]+)`")


def _cell(text: str) -> str:
    """reStructuredText literals and roles as Markdown code, in one table cell."""
    text = _ROLE.sub(r"`\1`", text).replace("``", "`")
    return text.replace("|", "\\|").replace("\n", " ")


def markdown_table() -> str:
    """:func:`rows` as one Markdown table per section."""
    out: list[str] = []
    section = ""
    for row in rows():
        head, _, name = row.key.rpartition(".")
        if head != section:
            section = head
            out += ["", f"### [{section}]", "", "| key | default | meaning |", "|---|---|---|"]
        out.append(f"| `{name}` | `{_cell(toml_value(row.default))}` | {_cell(row.description)} |")
    return "\n".join(out).strip() + "\n"
