"""Sampling of a sweep's parameter space: the full grid and the Latin hypercube (:mod:`soro.sweep`)."""
import itertools
import math

import numpy as np

from sorofem.errors import ParameterError

from .schema import _check_kinds, _check_value, _err, _is_number

__all__ = ["grid", "latin_hypercube"]


def _grid_values(key, spec, source=""):
    """The list of values of one grid parameter."""
    if isinstance(spec, dict):
        if set(spec) == {"choices"}:
            spec = spec["choices"]
        elif set(spec) == {"linspace"}:
            ls = spec["linspace"]
            if not (isinstance(ls, list) and len(ls) == 3 and all(_is_number(x) for x in ls)
                    and isinstance(ls[2], int) and ls[2] >= 1):
                raise _err(source, key, f"linspace must be [lo, hi, n] with n a positive integer, got {ls!r}")
            _check_value(ls, key, source)
            return [float(x) for x in np.linspace(ls[0], ls[1], ls[2])]
        elif "range" in spec:
            raise _err(source, key, "a range is sampled by mode = \"lhs\"; a grid needs values: a list, "
                                    "{ choices = [...] } or { linspace = [lo, hi, n] }")
        else:
            raise _err(source, key, f"unknown form {sorted(spec)}; use a list of values, {{ choices = [...] }} "
                                    "or { linspace = [lo, hi, n] }")
    if not isinstance(spec, list):
        raise _err(source, key, f"a grid parameter is a list of values, got {spec!r} (a value that does not "
                                "vary belongs in [fixed])")
    if not spec:
        raise _err(source, key, "the list of values is empty")
    _check_kinds(key, spec, source)
    return [_check_value(v, f"{key}[{i}]", source) for i, v in enumerate(spec)]


def _lhs_spec(key, spec, source=""):
    """("range", lo, hi) or ("choices", values) for one Latin-hypercube parameter."""
    if isinstance(spec, dict):
        if set(spec) == {"choices"}:
            values = spec["choices"]
            if not isinstance(values, list) or not values:
                raise _err(source, key, f"choices must be a non-empty list, got {values!r}")
            _check_kinds(key, values, source)
            return ("choices", [_check_value(v, f"{key}.choices[{i}]", source) for i, v in enumerate(values)])
        if set(spec) == {"range"}:
            spec = spec["range"]
        elif "linspace" in spec:
            raise _err(source, key, "linspace makes grid values; in lhs mode give a range [lo, hi]")
        else:
            raise _err(source, key, f"unknown form {sorted(spec)}; in lhs mode use [lo, hi], a list of names "
                                    "or { choices = [...] }")
    if isinstance(spec, (list, tuple)) and spec and all(isinstance(v, str) for v in spec):
        return ("choices", list(spec))
    if not (isinstance(spec, (list, tuple)) and len(spec) == 2 and all(_is_number(v) for v in spec)):
        raise _err(source, key, f"in lhs mode a parameter is a range [lo, hi] of two numbers, a list of names "
                                f"or {{ choices = [...] }}, got {spec!r}")
    lo, hi = (float(v) for v in spec)
    if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
        raise _err(source, key, f"the range [lo, hi] needs finite lo < hi, got [{spec[0]}, {spec[1]}]")
    return ("range", lo, hi)


# ---------------------------------------------------------------------------------------------- sampling
def grid(parameters):
    """Every combination of the parameters' values, in order, the last parameter varying fastest.

    Parameters
    ----------
    parameters : dict
        ``name -> list of values`` (or ``{"choices": [...]}``, ``{"linspace": [lo, hi, n]}``).

    Returns
    -------
    list of dict, one per case (``prod(len(values))`` cases).
    """
    names = list(parameters)
    values = [_grid_values(k, parameters[k]) for k in names]
    return [dict(zip(names, combo)) for combo in itertools.product(*values)]


def latin_hypercube(parameters, samples, seed=0):
    """A Latin hypercube sample of ``samples`` cases.

    For each parameter independently, :math:`u_i = (\\pi_i + r_i)/n`, :math:`i = 0..n-1`, with
    :math:`\\pi` a random permutation of :math:`0..n-1` and :math:`r_i` uniform in [0, 1): exactly one
    sample falls in each of the n strata :math:`[k/n, (k+1)/n)`. A range ``[lo, hi]`` maps it to
    :math:`lo + (hi - lo) u` (so lo <= value < hi); choices :math:`c_0..c_{k-1}` to :math:`c_{\\lfloor k u
    \\rfloor}` (each choice drawn with probability 1/k, n/k times up to one).

    Parameters
    ----------
    parameters : dict
        ``name -> [lo, hi]`` (a range), a list of names, ``{"range": [lo, hi]}`` or ``{"choices": [...]}``.
    samples : int
        Number of cases n >= 1.
    seed : int
        Seed of :func:`numpy.random.default_rng`; the same seed and parameters give the same cases.
    """
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise ParameterError(f"samples must be a positive integer, got {samples!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError(f"seed must be a non-negative integer, got {seed!r}")
    n = int(samples)
    rng = np.random.default_rng(int(seed))
    columns = {}
    for name, raw in parameters.items():
        spec = _lhs_spec(name, raw)
        u = (rng.permutation(n) + rng.random(n)) / n
        if spec[0] == "range":
            lo, hi = spec[1], spec[2]
            columns[name] = [min(lo + (hi - lo) * float(x), math.nextafter(hi, lo)) for x in u]
        else:
            choices = spec[1]
            columns[name] = [choices[min(int(x * len(choices)), len(choices) - 1)] for x in u]
    return [{k: columns[k][i] for k in columns} for i in range(n)]
