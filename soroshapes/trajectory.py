r"""The one result type of every time integration in :mod:`soroshapes`.

:meth:`Shapes.simulate <soroshapes.shapes.Shapes.simulate>`, :meth:`Tree.simulate <soroshapes.tree.Tree.simulate>`,
:meth:`Model.simulate <soroshapes.model.Model.simulate>` and :meth:`Assembly.simulate
<soroshapes.constraints.Assembly.simulate>` all return a :class:`Trajectory`: the recorded times ``t`` and whichever
of the fields below the run has, each with one row per recorded time.

==================  ===========  ======================================================================
field               shape        meaning
==================  ===========  ======================================================================
``t``               (m,)         recorded times [s] (always present)
``x``               (m, n)       stacked states of a network (:class:`~soroshapes.model.Model`)
``u``               (m, k)       inputs: controller outputs and couplings of a network or one system
``q``, ``qd``       (m, n)       generalized coordinates and their rates (beams, trees, assemblies)
``kinetic``         (m,)         kinetic energy [J]
``potential``       (m,)         elastic + gravity energy [J]; ``total`` = kinetic + potential
``tip``             (m, 3)       tip position [m] (a beam's end; an assembly's last body)
``drift_position``  (m,)         largest constraint drift [m] (constrained runs)
``drift_rotation``  (m,)         largest constraint drift [rad] (constrained runs)
``reactions``       (m, c, 6)    reaction wrench of each constraint, world frame, moment first [N m, N]
``volume``          (m,)         a reservoir's volume [m^3] (one system of a network)
``pressure``        (m,)         a reservoir's gauge pressure [Pa] (one system of a network)
==================  ===========  ======================================================================

``stats`` holds the integrator's statistics, one schema for every integrator (:func:`run_stats` makes it):

================================  ==========================================================================
key                               meaning
================================  ==========================================================================
``steps``                         accepted time steps (int)
``newton_iterations``             Newton iterations (corrections solved) over the whole run, a total (int)
``newton_iterations_per_step``    ``newton_iterations / steps`` (float; 0 without steps)
``matrices``                      iteration matrices factored (a network counts each connected component's
                                  block; a beam each refresh of its Newton matrix) (int)
``jacobians``                     finite-difference Jacobians of the whole system formed (int)
``cut_steps``                     steps whose Newton failed and that were covered by smaller steps (int)
``rejected``                      steps repeated by the error test of adaptive stepping (0 in fixed steps)
``dt``                            the step [s] of a fixed-step run, the first step of an adaptive one
``method``                        the integrator (str)
``path``                          ``"compiled"``, ``"python"`` or ``"compiled, then python"`` (a beam whose
                                  compiled loop handed over)
``adaptive``                      error-controlled steps (bool)
``wall_time``                     wall-clock time of the run [s]
================================  ==========================================================================

An integrator adds its own keys after these (a beam's ``newton_iterations_by_step`` (steps,) and
``compiled_steps``; a network's ``evaluation_path(s)``, ``system_evaluations``, ``min_step``/``max_step``
with adaptive steps, ...). A network's trajectory names its systems in ``systems``; ``traj["name"]`` is that
system's share, a :class:`Trajectory` of its own (``t``, its states ``x`` and inputs ``u``, and ``q``/``qd``
for a beam or ``volume``/``pressure`` for a reservoir). Asking for a field the run does not have raises an
:class:`AttributeError` that names the fields it has.

>>> import numpy as np
>>> tr = Trajectory(np.array([0.0, 0.1]), q=np.zeros((2, 3)), qd=np.ones((2, 3)))
>>> tr.fields
('q', 'qd')
>>> tr.tip
Traceback (most recent call last):
...
AttributeError: this trajectory has no 'tip': it has t, q, qd, stats
"""
import numpy as np

from sorofem.errors import ParameterError

__all__ = ["Trajectory", "FIELDS", "STATS_KEYS", "run_stats"]

#: The fields a trajectory may carry, in the order they are listed.
FIELDS = ("x", "u", "q", "qd", "kinetic", "potential", "tip", "drift_position", "drift_rotation", "reactions",
          "volume", "pressure")

#: The keys every integrator's ``stats`` holds, with the same meaning (module docstring).
STATS_KEYS = ("steps", "newton_iterations", "newton_iterations_per_step", "matrices", "jacobians", "cut_steps",
              "rejected", "dt", "method", "path", "adaptive", "wall_time")


def run_stats(*, steps, newton_iterations, matrices, jacobians, cut_steps, rejected, dt, method, path, adaptive,
              wall_time, **extra):
    """The ``stats`` dict of one run in the one schema (the module docstring's table), then the integrator's
    ``extra`` keys. Counts are totals over the run; ``newton_iterations_per_step`` is derived here.

    >>> st = run_stats(steps=4, newton_iterations=10, matrices=1, jacobians=0, cut_steps=0, rejected=0, dt=1e-3,
    ...                method="trapezoidal", path="compiled", adaptive=False, wall_time=0.01)
    >>> st["newton_iterations_per_step"], tuple(st) == STATS_KEYS
    (2.5, True)
    """
    steps, its = int(steps), int(newton_iterations)
    out = {"steps": steps, "newton_iterations": its, "newton_iterations_per_step": its / steps if steps else 0.0,
           "matrices": int(matrices), "jacobians": int(jacobians), "cut_steps": int(cut_steps),
           "rejected": int(rejected), "dt": float(dt), "method": str(method), "path": str(path),
           "adaptive": bool(adaptive), "wall_time": float(wall_time)}
    clash = set(extra) & set(out)
    if clash:
        raise ParameterError(f"run_stats: {sorted(clash)} are schema keys, not extra ones")
    out.update(extra)
    return out


class Trajectory:
    """Recorded times ``t`` [s] and the fields of one run (see the module docstring for each field's shape and
    unit); ``stats`` the integrator's statistics; ``traj["name"]`` one system of a network.

    Parameters
    ----------
    t : (m,) array, the recorded times [s].
    stats : dict, optional; the integrator's statistics.
    systems : dict, optional; name -> :class:`Trajectory` of each system of a network, in the network's order.
    name : str, optional; the system's name (a share of a network).
    **fields : the fields of :data:`FIELDS` the run has, each with m rows; None means absent.
    """

    def __init__(self, t, *, stats=None, systems=None, name=None, **fields):
        unknown = sorted(set(fields) - set(FIELDS))
        if unknown:
            raise ParameterError(f"Trajectory: unknown field(s) {unknown}; the fields are {', '.join(FIELDS)}")
        t = np.asarray(t, dtype=float).reshape(-1)
        d = self.__dict__
        d["t"] = t
        present = []
        for key in FIELDS:
            value = fields.get(key)
            if value is None:
                continue
            value = np.asarray(value)
            if value.ndim == 0 or value.shape[0] != len(t):
                raise ParameterError(f"Trajectory: field {key!r} has shape {value.shape}; it needs one row per "
                                     f"recorded time ({len(t)})")
            d[key] = value
            present.append(key)
        d["fields"] = tuple(present)
        d["stats"] = {} if stats is None else dict(stats)
        d["name"] = name
        systems = {} if systems is None else dict(systems)
        for key, sub in systems.items():
            if not isinstance(sub, Trajectory):
                raise ParameterError(f"Trajectory: system {key!r} must be a Trajectory, got {type(sub).__name__}")
        d["_systems"] = systems

    @property
    def systems(self):
        """Names of the systems of a network's trajectory (empty for a single body's run)."""
        return tuple(self._systems)

    @property
    def total(self):
        """Total mechanical energy [J]: ``kinetic + potential``."""
        return self.kinetic + self.potential

    def __getitem__(self, name):
        systems = self.__dict__["_systems"]
        if name not in systems:
            if not systems:
                raise KeyError(f"no system {name!r}: this trajectory is of a single system, not a network; read "
                               f"its fields ({', '.join(('t',) + self.fields)}) as attributes")
            raise KeyError(f"no system {name!r}; systems: {', '.join(systems)}")
        return systems[name]

    def __getattr__(self, key):
        # only called when normal lookup fails: a field the run does not have (or a property's missing operand)
        if key.startswith("__") or "fields" not in self.__dict__:
            raise AttributeError(key)
        have = ", ".join(("t",) + self.__dict__["fields"] + ("stats",))
        if key == "total":
            raise AttributeError(f"this trajectory has no energies, so no 'total': it has {have}")
        raise AttributeError(f"this trajectory has no {key!r}: it has {have}")

    def __repr__(self):
        span = f"{self.t[0]:.6g}..{self.t[-1]:.6g} s" if len(self.t) else "empty"
        who = f" {self.name!r}" if self.name else ""
        sys_ = f", systems {list(self._systems)}" if self._systems else ""
        return f"<Trajectory{who}: {len(self.t)} records, {span}, fields {list(self.fields)}{sys_}>"
