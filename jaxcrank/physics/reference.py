"""Reference values of the source paper, read from the packaged data file.

The numbers live in ``jaxcrank/data/paper_reference.toml``, which names the paper and
the table, figure or section each group of numbers comes from. Code that needs one of
them (the ``paper`` preset's Table 1 values, the paper's optimum in ``result.json``)
reads it here instead of repeating it.
"""

import tomllib
from functools import cache
from importlib import resources
from types import MappingProxyType

DATA_FILE = "paper_reference.toml"


@cache
def _load() -> MappingProxyType:
    text = resources.files("jaxcrank").joinpath("data", DATA_FILE).read_text(encoding="utf-8")
    data = tomllib.loads(text)
    return MappingProxyType({k: MappingProxyType(v) if isinstance(v, dict) else v for k, v in data.items()})


def load() -> MappingProxyType:
    """All reference values of the paper.

    Returns:
        A read-only mapping of sections to read-only mappings of values: ``source``
        (title, journal, model), ``table_1`` (lengths m, masses kg, inertias kg m^2,
        pin and hole radii m, crank speed rpm), ``deviations`` (m) and ``optimisation``
        (design bounds m, optimum deg, reduction percent, iterations). Each section but
        ``source`` has a ``where`` entry naming its place in the paper. Key names end
        in their unit.
    """
    return _load()


def value(section: str, key: str):
    """One reference value.

    Args:
        section: a section of the data file, e.g. ``"optimisation"``.
        key: a key in that section, e.g. ``"optimum_deg"``.

    Returns:
        The value as stored (a float, int, string or list), in the unit its key names.

    Raises:
        KeyError: naming the section or key that does not exist and the ones that do.
    """
    data = _load()
    if section not in data:
        raise KeyError(f"no section {section!r} in {DATA_FILE}; sections: {', '.join(data)}")
    if key not in data[section]:
        raise KeyError(f"no key {key!r} in section {section!r} of {DATA_FILE}; keys: {', '.join(data[section])}")
    return data[section][key]
