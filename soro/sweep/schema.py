"""The sweep configuration (format in :mod:`soro.sweep`): its keys, the types of ``[solve]`` and of declared
parameters, the checks of every value (each error names its key), and the ``"file.py:function"`` /
``"package.module:function"`` references of the builder and summary."""
import hashlib
import importlib
import importlib.util
import math
import os
import sys
import warnings
from pathlib import Path

from sorofem.errors import ParameterError

__all__ = ["MODES", "SOLVE_KEYS", "SOLVE_TYPES", "RENAMED_SOLVE_KEYS", "PARAMETER_TYPES", "MAX_CELLS",
           "rename_solve_keys"]

MODES = ("grid", "lhs")
#: Keyword arguments of :meth:`sorofem.fem.Fem.solve` that ``[solve]`` (or a builder) may set.
SOLVE_KEYS = ("load_level", "steps", "min_step", "max_step", "max_iterations", "predictor", "monitor_stability")
_TOP_KEYS = ("builder", "summary", "sweep", "parameters", "fixed", "solve")
_SWEEP_KEYS = ("mode", "samples", "seed", "max_cells")
#: Default largest mesh (global cell count) a case may solve: a mistyped mesh size (1e-5 for 1e-3) fails the
#: case with the count and the limit instead of solving for hours.
MAX_CELLS = 1_000_000
#: The type of each ``[solve]`` setting: "number" (an int or a float, never a bool), "integer", "bool";
#: all numbers must be positive.
SOLVE_TYPES = {"load_level": "number", "steps": "integer", "min_step": "number", "max_step": "number",
               "max_iterations": "integer", "predictor": "bool", "monitor_stability": "bool"}
#: Old ``[solve]`` names still accepted, with a warning naming the new one: ``{old: new}``.
RENAMED_SOLVE_KEYS = {"t_end": "load_level"}
#: Parameter types a builder may declare in its ``parameters`` attribute (see the module docstring).
PARAMETER_TYPES = {float: "number", int: "integer", bool: "bool", str: "string", list: "list"}


# ---------------------------------------------------------------------------------------------- validation
def _err(source, key, problem):
    return ParameterError(f"{source}: {key}: {problem}" if source else f"{key}: {problem}")


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_value(v, key, source):
    """A case value: a finite number, a string, a bool or a list of those (JSON round-trips it exactly)."""
    if isinstance(v, bool) or isinstance(v, str):
        return v
    if _is_number(v):
        if not math.isfinite(v):
            raise _err(source, key, f"{v} is not a finite number")
        return v
    if isinstance(v, (list, tuple)):
        return [_check_value(x, f"{key}[{i}]", source) for i, x in enumerate(v)]
    raise _err(source, key, f"values must be numbers, strings, booleans or lists of them, got "
                            f"{type(v).__name__} {v!r}")


def _type_name(v):
    if isinstance(v, bool):
        return "bool"
    if isinstance(v, int):
        return "integer"
    if isinstance(v, float):
        return "number"
    return {str: "string", list: "list", tuple: "list"}.get(type(v), type(v).__name__)


def _check_type(v, want, key, source):
    """``v`` is of the type ``want`` ("number", "integer", "bool", "string" or "list"): bools are not numbers,
    and an integer setting is an integer (``2.7`` or ``2.0`` is refused, not truncated)."""
    ok = {"number": _is_number(v), "integer": isinstance(v, int) and not isinstance(v, bool),
          "bool": isinstance(v, bool), "string": isinstance(v, str), "list": isinstance(v, (list, tuple))}[want]
    if not ok:
        article = "an" if want[0] in "aeiou" else "a"
        raise _err(source, key, f"must be {article} {want}, got {_type_name(v)} {v!r}")


def rename_solve_keys(solve, source=""):
    """Rename the old ``[solve]`` keys of :data:`RENAMED_SOLVE_KEYS` in place, warning once per key.

    Parameters
    ----------
    solve : dict
        ``[solve]`` settings (or the keyword arguments a builder returns); changed in place.
    source : str
        Where the settings come from (the configuration file or the builder), named in the messages.

    Raises
    ------
    ParameterError
        When both the old and the new name are set.
    """
    for old, new in RENAMED_SOLVE_KEYS.items():
        if old not in solve:
            continue
        if new in solve:
            raise _err(source, f"solve.{old}", f"is the old name of solve.{new}, which is also set: keep only {new}")
        where = f"{source}: " if source else ""
        warnings.warn(f"{where}solve.{old} is deprecated: write solve.{new} (the final load level of "
                      f"Fem.solve)", FutureWarning, stacklevel=3)
        solve[new] = solve.pop(old)
    return solve


def _check_solve(solve, source):
    """Check ``[solve]``'s keys, types and signs (old keys renamed in place first, with a warning)."""
    rename_solve_keys(solve, source)
    for k, v in solve.items():
        if k not in SOLVE_KEYS:
            raise _err(source, f"solve.{k}", f"not a setting of Fem.solve; use one of {', '.join(SOLVE_KEYS)}")
        _check_type(v, SOLVE_TYPES[k], f"solve.{k}", source)
        _check_value(v, f"solve.{k}", source)
        if SOLVE_TYPES[k] != "bool" and not v > 0:
            raise _err(source, f"solve.{k}", f"must be positive, got {v!r}")


def _check_kinds(key, values, source):
    """The values of one parameter are of one kind: numbers (ints and floats mix), bools, strings or lists."""
    kinds = {("number" if _is_number(v) else _type_name(v)) for v in values}
    if len(kinds) > 1:
        raise _err(source, key, f"mixes {' and '.join(sorted(kinds))} values {values!r}; a parameter's values "
                                "are all of one type (true/false are not 1/0)")


def _check_declared(cases, declared, builder_spec, source, fixed=()):
    """Check every case value against the types the builder declares (``build.parameters``)."""
    if declared is None:
        return
    if not isinstance(declared, dict) or not all(t in PARAMETER_TYPES for t in declared.values()):
        raise _err(source, "builder", f"{builder_spec}.parameters must map names to types among "
                                      f"{', '.join(t.__name__ for t in PARAMETER_TYPES)}, got {declared!r}")
    for params in cases:
        for k, v in params.items():
            key = f"fixed.{k}" if k in fixed else f"parameters.{k}"
            if k not in declared:
                raise _err(source, key, f"the builder {builder_spec} takes no parameter {k!r}; it declares "
                                        f"{', '.join(declared)}")
            _check_type(v, PARAMETER_TYPES[declared[k]], key, source)


def _is_material_key(name):
    return name == "material" or name.endswith("_material")


def _check_material(name, value, source):
    from sorofem.materials import PRESETS

    if not isinstance(value, str) or value not in PRESETS:
        raise _err(source, name, f"unknown material preset {value!r}; known presets: {', '.join(PRESETS)}")


# ---------------------------------------------------------------------------------------------- builders
def _resolve(spec, base_dir, key, source):
    """A function from ``"file.py:function"`` (relative to ``base_dir``) or ``"package.module:function"``."""
    if callable(spec):
        return spec
    if not isinstance(spec, str) or ":" not in spec:
        raise _err(source, key, f"expected \"file.py:function\" or \"package.module:function\", got {spec!r}")
    target, _, name = spec.rpartition(":")
    if not target or not name.isidentifier():
        raise _err(source, key, f"expected \"file.py:function\" or \"package.module:function\", got {spec!r}")
    if target.endswith(".py") or "/" in target or os.sep in target:
        path = Path(target)
        if not path.is_absolute():
            path = Path(base_dir or ".") / path
        if not path.is_file():
            raise _err(source, key, f"no file {path} (a relative path is taken from the config's folder)")
        path = path.resolve()
        # registered in sys.modules under a name unique to the file (dataclasses, pickle look modules up there)
        module_name = f"soro_sweep_{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:8]}"
        try:
            mod_spec = importlib.util.spec_from_file_location(module_name, path)
            module = importlib.util.module_from_spec(mod_spec)
            sys.modules[module_name] = module
            mod_spec.loader.exec_module(module)
        except Exception as e:  # noqa: BLE001 - re-raised with the key that named the file
            sys.modules.pop(module_name, None)
            raise _err(source, key, f"importing {path} failed: {type(e).__name__}: {e}") from e
        where = str(path)
    else:
        try:
            module = importlib.import_module(target)
        except ImportError as e:
            raise _err(source, key, f"cannot import module {target!r} ({e})") from e
        where = f"module {target}"
    fn = getattr(module, name, None)
    if not callable(fn):
        raise _err(source, key, f"{where} has no function {name!r}")
    return fn


def _describe(spec):
    """How a builder or summary is named in tables and the manifest."""
    if isinstance(spec, str):
        return spec
    return f"{getattr(spec, '__module__', '?')}:{getattr(spec, '__qualname__', spec)}"
