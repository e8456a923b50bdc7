"""Units without pint's start-up (study.common.units): every spelling of the table against pint, bit for bit, and
pint still reading (and converting) every other unit."""
import subprocess
import sys

import numpy as np
import pytest

from study.common.errors import UserError
from study.common.units import KNOWN, SI_NAMES, conversion_factor, convert_values, parse_unit, units

TARGETS = ("s", "m", "m/s", "m/s^2", "rad", "N", "W", "dimensionless", "km/h", "ms", "deg", "kW", "ft")


@pytest.mark.parametrize("text", sorted(KNOWN))
def test_table_entry_is_pints_own(text):
    """Name, dimension and the factor to the SI unit of the dimension are pint's, exactly."""
    ur = units()
    pu = ur.Unit(text)
    u = parse_unit(text)
    assert u.name == str(pu)
    assert u.dimension == tuple(sorted(dict(pu.dimensionality).items()))
    assert u.dimension_text == str(ur.Unit(SI_NAMES[u.dimension]).dimensionality)
    si = ur.Unit(SI_NAMES[u.dimension])
    assert u.factor == ur._get_conversion_factor(pu._units, si._units)


@pytest.mark.parametrize("text", sorted(KNOWN))
def test_conversion_equals_pint_bit_for_bit(text):
    """Values converted to every target of the same dimension are the floats pint gives (to SI from the table)."""
    ur = units()
    values = np.random.default_rng(7).normal(0.0, 1e3, 257)
    src = parse_unit(text)
    for target in TARGETS:
        dst = parse_unit(target)
        if dst.dimension != src.dimension:
            with pytest.raises(UserError):
                conversion_factor(src, dst)
            continue
        ours = convert_values(values, src, dst)
        if str(ur.Unit(text)) == str(ur.Unit(target)):
            theirs = values
        else:
            theirs = np.asarray(ur.Quantity(values, ur.Unit(text)).to(ur.Unit(target)).magnitude, dtype="float64")
        assert ours.tobytes() == theirs.tobytes(), (text, target)
        assert conversion_factor(src, dst) == float(ur.Quantity(1.0, ur.Unit(text)).to(ur.Unit(target)).magnitude)


def test_other_spellings_are_read_by_pint():
    """A unit outside the table (another spelling, another unit) is pint's, converted by pint."""
    u = parse_unit("kilometer / hour")
    assert (u.name, u.factor) == ("kilometer / hour", None)
    assert u.dimension == parse_unit("km/h").dimension
    assert convert_values(np.array([36.0]), u, parse_unit("m/s"))[0] == pytest.approx(10.0)
    lbf = parse_unit("lbf")
    assert lbf.dimension == parse_unit("N").dimension and lbf.dimension_text == "[mass] * [length] / [time] ** 2"
    with pytest.raises(UserError, match="unknown unit 'kmh/x'"):
        parse_unit("kmh/x")
    with pytest.raises(UserError, match="needs a unit"):
        parse_unit(" ")


def test_the_usual_units_load_no_pint():
    """Reading a log mapping and a route in the usual units and converting with them leaves pint unimported."""
    code = ("import sys, numpy as np\n"
            "from study.folder.logmap import convert\n"
            "from study.common.units import parse_unit, conversion_factor\n"
            "convert(np.arange(3.0), 'mph', 'm/s'); convert(np.arange(3.0), '%', 'rad', 'grade')\n"
            "conversion_factor(parse_unit('km/h'), parse_unit('m/s'))\n"
            "print('pint' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
