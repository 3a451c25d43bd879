"""Records of a sweep: the progress line of a case and the provenance of results (digests of the builder's
source files, ``[solve]``, ``[fixed]`` and the package version) that a resume compares (:mod:`soro.sweep`)."""
import hashlib
import inspect
import json
import os
from pathlib import Path

from .schema import _describe

__all__ = ["format_record", "provenance_changes"]

def format_record(rec, done=None, total=None):
    """One progress line for a case record: ``[3/12] case_0002  done     1.4 s  (4 steps, 1 rank)``."""
    count = f"[{done}/{total}] " if done is not None and total is not None else ""
    status = rec["status"]
    line = f"{count}{rec['id']}  {status:<6} {rec.get('wall_time_s') or 0.0:7.1f} s"
    if status == "done":
        ranks = rec.get("ranks", 1)
        line += f"  ({rec.get('steps')} steps, {ranks} rank{'s' if ranks != 1 else ''})"
    elif rec.get("error"):
        line += f"  {rec['error'].splitlines()[0][:200]}"
    return line


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.6g}"
    return json.dumps(v) if not isinstance(v, str) else v


# ---------------------------------------------------------------------------------------------- provenance
def _sha256(data):
    return hashlib.sha256(data if isinstance(data, bytes) else data.encode()).hexdigest()


def _canonical(obj):
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def _local_imports(path, base_dir):
    """Files of ``base_dir`` that the Python file ``path`` imports (``import x``, ``from x import y``,
    ``from x.y import z``, at any depth of the file), found from its syntax tree; and the files that a string
    literal of the file names: a data file of ``base_dir`` the builder reads (relative to ``base_dir`` or to the
    file's folder; not a ``.toml`` file: a sweep configuration's parameters may grow between runs), or a module
    loaded by path (``spec_from_file_location(..., Path(__file__).parents[1] / "case_lib.py")``): a literal
    ending in ``.py`` names the nearest such file in the file's folder or a folder above it."""
    import ast

    try:
        tree = ast.parse(Path(path).read_text(), filename=str(path))
    except (OSError, SyntaxError, ValueError):
        return []
    names, literals = [], []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module)
            names += [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and 0 < len(node.value) < 256 \
                and "\n" not in node.value and "\0" not in node.value:
            literals.append(node.value)
    found = []
    base, here = base_dir.resolve(), Path(path).resolve().parent
    for text in literals:
        module = text.endswith(".py")
        for candidate in [base / text, here / text] + ([p / text for p in here.parents] if module else []):
            try:
                real = candidate.resolve()
                ok = real.is_file() and real.suffix != ".toml" and (module or base in real.parents)
            except (OSError, ValueError):
                continue
            if ok:
                if real not in found:
                    found.append(real)
                if module:
                    break
    for name in names:
        parts = name.split(".")
        for n in range(1, len(parts) + 1):  # importing a.b.c runs a/__init__.py and a/b/__init__.py too
            rel = Path(*parts[:n])
            for candidate in (base_dir / rel.with_suffix(".py"), base_dir / rel / "__init__.py"):
                if candidate.is_file() and candidate.resolve() not in found:
                    found.append(candidate.resolve())
    return found


def _source_files(fn, base_dir):
    """The source file of ``fn`` and, recursively, the files of ``base_dir`` it imports."""
    try:
        first = Path(inspect.getsourcefile(fn)).resolve()
    except (TypeError, OSError):
        return []
    files, todo = [], [first]
    while todo:
        f = todo.pop()
        if f in files or not f.is_file():
            continue
        files.append(f)
        if base_dir is not None and f.suffix == ".py":
            todo += _local_imports(f, base_dir)
    return files


def _provenance(builder, summary, base_dir, solve, fixed):
    """What a case's results depend on besides its parameters: digests of the builder's (and summary's) source
    files and of the files they import from the configuration's folder, of ``[solve]`` and ``[fixed]``, and
    the package version."""
    from sorofem import __version__

    base = base_dir.resolve() if base_dir is not None else None
    files = {}
    for fn in (builder, summary):
        if fn is None:
            continue
        sources = _source_files(fn, base)
        if not sources:  # a callable without a source file: its code object stands for it
            code = getattr(fn, "__code__", None)
            files[f"<{_describe(fn)}>"] = _sha256(code.co_code + repr(code.co_consts).encode()) if code \
                else _sha256(_describe(fn))
        for f in sources:  # named relative to the configuration's folder: moving the whole tree changes nothing
            name = os.path.relpath(f, base) if base is not None else str(f)
            files[name] = _sha256(f.read_bytes())
    return {"package_version": __version__, "builder_sha256": _sha256(_canonical(files)), "builder_files": files,
            "solve_sha256": _sha256(_canonical(solve)), "solve": solve,
            "fixed_sha256": _sha256(_canonical(fixed)), "fixed": fixed}


def provenance_changes(old, new):
    """What differs between two provenance records (lists of phrases; empty if they match)."""
    if not isinstance(old, dict) or "builder_sha256" not in old:
        return ["the results were written before provenance was recorded"]
    changes = []
    if old.get("builder_sha256") != new["builder_sha256"]:
        a, b = old.get("builder_files") or {}, new["builder_files"]
        what = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
        changes.append(f"the builder's source changed ({', '.join(what) or 'unknown files'})")
    for key, table in (("solve", "[solve]"), ("fixed", "[fixed]")):
        if old.get(f"{key}_sha256") != new[f"{key}_sha256"]:
            a, b = old.get(key) or {}, new[key]
            diff = [f"{k} {json.dumps(a.get(k))} -> {json.dumps(b.get(k))}"
                    for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
            changes.append(f"{table} changed ({'; '.join(diff) or 'values'})")
    if old.get("package_version") != new["package_version"]:
        changes.append(f"the package version changed ({old.get('package_version')} -> {new['package_version']})")
    return changes
