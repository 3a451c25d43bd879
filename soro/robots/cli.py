"""``soro robot list`` and ``soro robot export NAME --out DIR [--units mm] [--param k=v ...]`` (the parser is
in :mod:`soro.cli`)."""
import sys

from sorofem.errors import SoroError

__all__ = ["run"]


def run(args, stream=None):
    """Run a parsed ``soro robot ...`` command; exit status 0, or 2 with the error's message."""
    from . import ROBOTS, UNITS, export, get, parse_params
    from sorofem.units import mm
    stream = stream or sys.stdout
    try:
        if args.robot_command == "list":
            for robot in ([get(args.name)] if args.name else ROBOTS.values()):
                print(f"{robot.name}: {robot.title}", file=stream)
                for prm in robot.PARAMS:
                    s = UNITS[prm.unit]
                    print(f"    {prm.name:<16} {prm.default / s:>8g} {prm.unit:<5} [{prm.lo / s:g}, {prm.hi / s:g}]  "
                          f"{prm.doc}", file=stream)
            return 0
        params = parse_params(args.name, args.param)
        res = args.resolution * mm if args.resolution is not None else None
        rep = export(args.name, args.out, units=args.units, params=params, resolution=res,
                     preview=not args.no_preview)
    except SoroError as e:
        print(f"soro robot: {e}", file=sys.stderr)
        return 2
    for name, part in rep["parts"].items():
        nets = part.get("networks", {})
        sealed = all(v["closed"] and v["inlet_open"] for v in nets.values())
        print(f"{args.out}/{part['file']}: {part['material']}, {part['triangles']} triangles, bbox "
              f"{' x '.join(f'{v:g}' for v in part['bbox_mm'])} mm, watertight {part['watertight']}, shells "
              f"{part['shells']}" + (f", networks {sorted(nets)} closed except the port: {sealed}" if nets else ""),
              file=stream)
    ok = all(p["watertight"] and p["shells"] == 1 and all(v["closed"] and v["inlet_open"]
                                                           for v in p.get("networks", {}).values())
             for p in rep["parts"].values())
    print(f"{args.out}/{args.name}.json, {args.out}/{rep['board_profile']} (board profile: each channel's "
          f"safety limits p_min/p_max are the seed's range of its network, enforced by the board server)"
          + (f", {args.out}/{rep['preview']}" if "preview" in rep else ""), file=stream)
    return 0 if ok else 1
