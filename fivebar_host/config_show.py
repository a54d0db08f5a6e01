"""The profile shown to a person: `fivebar config show` (every key, its value and where it
came from) and `fivebar config check` (the parsed profile, in the profile's own units).
Apart from `config` so that reading a profile and presenting one stay separate concerns."""

from __future__ import annotations

import json
import math
from dataclasses import fields
from pathlib import Path
from typing import Any

from fivebar_host.config import (
    DEFAULT_PROFILE,
    GENERIC_KEYS,
    Profile,
    merged_document,
    parse_profile,
)

__all__ = ["describe", "show_lines"]


def show_lines(path: str | Path | None = None) -> list[str]:
    """`fivebar config show`: every key of the profile with its value and the file it came
    from (the profile, or the bundled default it inherits). Validates the profile first."""
    p = Path(path) if path is not None else DEFAULT_PROFILE
    doc, sources = merged_document(p)
    parse_profile(doc, str(p))
    inherited = sum(1 for src in sources.values() if src != str(p))
    lines = [f"profile {p}" + (f" ({inherited} keys from the bundled default "
                               f"{DEFAULT_PROFILE})" if inherited else "")]
    width = max((len(k) for _, k in sources), default=0)
    for table, keys in doc.items():
        lines.append(f"[{table}]")
        for key, value in keys.items():
            src = sources[(table, key)]
            mark = "profile" if src == str(p) else "default"
            lines.append(f"  {key:<{width}} = {_toml_value(value):<24} # {mark}")
    return lines


def _toml_value(v: Any) -> str:
    """A value as TOML writes it (numbers, booleans, strings, nested lists)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    return repr(v)


def describe(profile: Profile) -> str:
    """Human-readable summary of a parsed profile (for `fivebar config check`)."""
    lines = [f"profile {profile.source}"]
    names = ["geometry", "motors", "kinematics", "motion", "laser", "serial"]
    lines.append(f"[tool]\n  kind = {profile.tool!r}")
    for name in names + (["pen"] if profile.pen is not None else []):
        obj = getattr(profile, name)
        lines.append(f"[{name}]")
        for f in fields(obj):
            v = getattr(obj, f.name)
            if f.name.endswith(("_rad", "_angle")) and isinstance(v, float):
                lines.append(f"  {f.name.removesuffix('_rad')}_deg = {math.degrees(v):g}")
            elif f.name == "home_rad":
                lines.append(f"  home_deg = [{', '.join(f'{math.degrees(x):g}' for x in v)}]")
            elif f.name == "limits_rad":
                lines.append("  limits_deg = [" + ", ".join(
                    f"[{math.degrees(lo):g}, {math.degrees(hi):g}]" for lo, hi in v) + "]")
            else:
                lines.append(f"  {f.name} = {v!r}")
        if name == "motors":
            mot = profile.motors
            lines.append(f"  # steps_per_rev = {mot.steps_per_rev:g} "
                         f"({math.degrees(mot.rad_per_step):.5f}° per step)")
    tx = profile.text
    lines.append("[text]")
    lines.extend(f"  {k} = {tx.generic[g]!r}" for k, g in GENERIC_KEYS.items())
    lines += [f"  default = {tx.default!r}", f"  fallback = {tx.fallback!r}",
              f"  font_dirs = {list(tx.font_dirs)!r}", f"  aliases = {dict(tx.aliases)!r}"]
    return "\n".join(lines)
