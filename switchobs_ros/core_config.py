"""From parameter values to switchobs_core objects: system, cycles, gain table.

Shared by the estimator and camera_sim. Every failure is a :class:`ConfigError` with one
line that says what is wrong and what to do.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
from collections.abc import Callable
from pathlib import Path

from switchobs_core import __version__
from switchobs_core.exceptions import SwitchobsError, one_line
from switchobs_core.families import FAMILY_NAMES, design_family_table, family_entry
from switchobs_core.files import check_private, kind_of
from switchobs_core.model.disturbance import Disturbance
from switchobs_core.model.noise import NoiseModel
from switchobs_core.model.scenarios import load_disturbance, load_noise, load_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.model.system import LTISystem
from switchobs_core.ranges import MAX_CYCLES
from switchobs_core.table.ahead import TableReadAhead
from switchobs_core.table.check import verify_table
from switchobs_core.table.gains import GainTable

from .params import ConfigError

__all__ = [
    "DEFAULT_X0",
    "SensorOutputs",
    "GAIN_FAMILY_PARAM",
    "noise_from_params",
    "disturbance_from_params",
    "cycles_from_params",
    "load_or_design_table",
    "load_system_param",
    "table_cache_path",
    "CacheDir",
    "cache_dir_param",
    "check_cache_private",
]


#: Default true initial state of the simulated paper scene (camera moving, agents drifting in x;
#: the unstable v_y modes start at rest so a 30 s demo stays bounded): x = [chi_c; chi_1; chi_2],
#: chi = [p, v]. camera_sim, the bag generator and the demo start from it.
DEFAULT_X0 = (0.0, 0.0, 0.2, 0.1, 3.0, 1.0, -0.1, 0.0, -2.0, 2.0, 0.1, 0.0)

#: Values of the ``gain_family`` parameter ('' = the table's family).
GAIN_FAMILY_PARAM = ("", *FAMILY_NAMES)


def disturbance_from_params(cfg: dict, system: LTISystem) -> Disturbance | None:
    """The declared disturbance: the system's ``disturbance:`` section (built-in scenarios: unit
    accelerations on the velocity states, no bound), then the parameter ``disturbance.max``
    (empty: keep); None when the system has no disturbance input and none is asked for."""
    w_max = cfg.get("disturbance.max", ())
    try:
        dist = load_disturbance(cfg["system"], system, w_max=tuple(w_max) if isinstance(w_max, (list, tuple)) else
                                (w_max,))
    except SwitchobsError as err:
        raise ConfigError(f"parameter {err}" if str(err).startswith("disturbance.max") else
                          f"parameter 'disturbance.max': {err}") from None
    return dist if dist.q else None


def noise_from_params(cfg: dict, system: LTISystem, disturbance: Disturbance | None = None) -> NoiseModel:
    """The noise model: the system's ``noise:`` section (or the defaults), then the parameters
    ``noise.measurement_std`` / ``noise.process_std`` where they are >= 0; with an active
    ``disturbance`` and no process noise given, ``Q_c = B_w diag(max^2) B_w'``."""
    meas = cfg.get("noise.measurement_std", -1.0)
    proc = cfg.get("noise.process_std", -1.0)
    try:
        return load_noise(cfg["system"], system, meas_std=None if meas < 0 else meas,
                          process_q=None if proc < 0 else proc, disturbance=disturbance)
    except SwitchobsError as err:
        raise ConfigError(f"parameters 'noise.*': {err}") from None


def load_system_param(spec: str) -> LTISystem:
    """``system`` parameter: a built-in scenario name or a YAML file path."""
    try:
        return load_system(spec)
    except SwitchobsError as err:
        raise ConfigError(f"parameter 'system': {err}") from None
    except Exception as err:
        raise ConfigError(f"parameter 'system': cannot load '{spec}': {type(err).__name__}: {err}") from None


def cycles_from_params(mode: str, tau: tuple, s: tuple, h: tuple, N: int, dead_time: float = 0.0) -> list[Cycle]:
    """The cycle list of a schedule given by ``schedule.tau``/``schedule.s`` (two channels)
    or ``schedule.h`` (N channels: N active times per cycle, cycles concatenated), every cycle
    with the blind interval ``schedule.dead_time`` after each switch.
    """
    n_cycles = len(h) // max(N, 1) if h else len(tau)
    if n_cycles > MAX_CYCLES:
        raise ConfigError(f"schedule: {n_cycles} cycles given, at most {MAX_CYCLES} supported (a schedule repeats its "
                          "cycles: give one period)")
    try:
        if h:
            if len(h) % N:
                raise ConfigError(f"parameter 'schedule.h' has {len(h)} values; expected a multiple of N = {N} "
                                  "(N active times per cycle)")
            cycles = [Cycle(h[k:k + N], dead_time) for k in range(0, len(h), N)]
        else:
            if N != 2:
                raise ConfigError(f"the system has N = {N} channels: give 'schedule.h' (N active times per "
                                  "cycle) instead of schedule.tau/schedule.s")
            if len(tau) != len(s) or not tau:
                raise ConfigError(f"parameters 'schedule.tau' ({len(tau)} values) and 'schedule.s' "
                                  f"({len(s)} values) must have the same, non-zero length")
            cycles = [Cycle.from_ts(t, si, dead_time) for t, si in zip(tau, s)]
    except SwitchobsError as err:
        raise ConfigError(f"schedule: {err}") from None
    if mode == "periodic" and len(cycles) != 1:
        raise ConfigError(f"schedule.mode 'periodic' takes one cycle; got {len(cycles)} (use 'sequence')")
    return cycles


def table_cache_path(cache_dir: str, system: LTISystem, mode: str, cycles: list[Cycle],
                     robust: tuple[float, float] | None, delta: float, *, family: str = "lmi",
                     rate: float = 0.0, noise: NoiseModel | None = None) -> Path:
    """Where a gain table designed at start-up is cached: keyed by everything it depends on."""
    spec = {"fingerprint": system.fingerprint(), "mode": mode,
            "cycles": [list(c.h) for c in cycles], "robust": robust, "delta": delta,
            "version": __version__}
    if any(c.dead_time for c in cycles):        # (tables without one keep their cache key)
        spec["dead_time"] = max(c.dead_time for c in cycles)
    if family_entry(family).rate:
        spec.update(family=family, rate=rate, noise=None if noise is None else noise.fingerprint())
    key = json.dumps(spec, sort_keys=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    safe = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in system.name)
    return Path(os.path.expanduser(cache_dir)) / f"{safe}-{digest}.npz"   # the compact container (any size loads)


def load_or_design_table(path: str, cache_dir: str, system: LTISystem, mode: str,
                         cycles: list[Cycle], robust: tuple[float, float] | None, delta: float,
                         log: Callable[[str], None], *, family: str = "lmi", rate: float = 0.0,
                         noise: NoiseModel | None = None, warn: Callable[[str], None] | None = None,
                         ahead: TableReadAhead | None = None):
    """The gain table: from ``path``; else from the cache; else designed now and cached.

    ``family`` says what to design when there is no table: the paper's LMI gains, or offline
    Kalman gains for the cycle sequence at ``rate`` Hz under ``noise``. A cache that cannot be
    written (a read-only or full filesystem, a symlink loop) is said once on ``warn`` (default
    ``log``), and the start-up goes on with the designed table.
    ``ahead``: ``path``'s file already being read (:class:`~switchobs_core.table.ahead.TableReadAhead`),
    taken instead of a read here: the same table or refusal.
    Returns ``(table, where)`` with ``where`` the file the table came from or went to.
    """
    if path:
        file = os.path.expanduser(path)
        try:
            if ahead is not None and ahead.path == Path(file):
                table = ahead.table(system)
            else:
                table = GainTable.load(file, system=system)
            verify_table(table, system, source=f"gain table {path}")
        except SwitchobsError as err:
            raise ConfigError(f"parameter 'gain_table': {err}") from None
        return table, Path(path)
    entry = family_entry(family)
    if entry.rate:
        if mode == "robust" and entry.robust != entry.name:
            raise ConfigError(f"gain_family '{family}' needs a known schedule (periodic or sequence); without one "
                              f"use gain_family '{entry.robust}'")
        if not rate > 0:
            raise ConfigError(f"gain_family '{family}' with no gain_table designs the table at start-up: set 'rate' "
                              "(the nominal sample rate in Hz)")
    cache = table_cache_path(cache_dir, system, mode, cycles, robust, delta, family=family, rate=rate, noise=noise)
    check_cache_private(cache, getattr(cache_dir, "trusted", False))
    if cache.exists():
        try:
            table = GainTable.load(cache, system=system)
            verify_table(table, system, source=f"cached gain table {cache}")
            log(f"gain_table not set: using the cached table {cache}")
            return table, cache
        except SwitchobsError as err:
            log(f"cached gain table {cache} unusable ({err}); designing again")
    log(f"gain_table not set: designing {family} gains for system '{system.name}', mode {mode}, "
        f"cycles {[c.label() for c in cycles]}, " + (f"rate {rate:g} Hz, {noise.describe()}" if entry.rate
                                                     else f"delta {delta} (takes a few seconds)"))
    try:
        table = design_family_table(family, system, cycles, robust=robust, delta=delta, rate=rate, noise=noise)
    except SwitchobsError as err:
        raise ConfigError(f"gain design failed: {err}") from None
    try:
        cache.parent.mkdir(mode=0o700, parents=True, exist_ok=True)    # private: see check_cache_private
        table.save(cache)
        log(f"wrote the designed gain table to {cache} (set gain_table to it to skip the design)")
    except (OSError, SwitchobsError) as err:
        why = err.strerror if isinstance(err, OSError) and err.strerror else one_line(err)
        (warn or log)(f"could not cache the gain table at {cache} ({why}): it is designed again at every start "
                      "until the cache can be written; fix gain_table_cache_dir, or save a table with "
                      "'switchobs design' and set gain_table to it")
    return table, cache


class SensorOutputs:
    """What a simulated system publishes per tick, by its input specification (camera_sim and
    ``switchobs_bag generate``): the channel message (when the specification has a channel
    topic), then one message per source serving the active channel with the rows of
    ``y = C_c x`` that its fields carry (only the shared sources while the camera turns)."""

    def __init__(self, specs):
        import msg_bridge as mb

        self.specs = specs
        self.writers = [mb.FieldWriter(s.type, s.fields) for s in specs.sources]

    def messages(self, channel: int, y, stamp_ns: int, frame_id: str, blind: bool = False,
                 switch_ns: int | None = None, shared_offset_ns: int = 0, *,
                 switching: bool = True) -> list[tuple[str, object]]:
        """``[(topic, message), ...]`` of one tick on ``channel`` with output ``y`` (relative topics).
        With ``switch_ns`` (the channel's switching instant, the stamp of its first tick) the channel
        message is a stamped ``switchobs_msgs/ActiveChannel``, else a ``std_msgs/UInt8``;
        ``shared_offset_ns`` shifts the stamps of the shared sources and of the switching instant (a
        camera computer whose clock is that far ahead of the targets').

        The order is camera_sim's: the channel message first on a ``switching`` tick (the first tick on
        ``channel``: the first pose of the new channel then finds its channel), and after the tick's
        measurements on the others: a repetition that proves their channel as it arrives (a channel
        message sent after a sample, ``2 x clock_tolerance_ms`` after it with a tolerance:
        :mod:`switchobs_ros.switching`, :mod:`switchobs_ros.attribution`)."""
        out: list[tuple[str, object]] = []
        for src, w in zip(self.specs.sources, self.writers):
            if src.serves(channel) and (src.shared or not blind):
                at = stamp_ns + (shared_offset_ns if src.shared else 0)
                out.append((src.topic, w.msg([y[r] for r in src.rows_for(channel)], at, frame_id)))
        if self.specs.channel_topic:
            if switch_ns is None:
                from std_msgs.msg import UInt8
                msg: tuple[str, object] = (self.specs.channel_topic, UInt8(data=int(channel)))
            else:
                from msg_bridge.typed import active_channel
                msg = (self.specs.channel_topic, active_channel(channel, switch_ns + shared_offset_ns))
            out.insert(0 if switching else len(out), msg)
        return out


class CacheDir(str):
    """The ``gain_table_cache_dir`` value, carrying whether ``gain_table_cache_trusted`` names it
    (:func:`cache_dir_param`): a ``str`` everywhere else."""

    trusted: bool = False


def cache_dir_param(cache_dir: str, trusted: str) -> CacheDir:
    """``gain_table_cache_dir``, trusted when ``gain_table_cache_trusted`` names the same folder."""
    out = CacheDir(cache_dir)
    if trusted:
        real = os.path.realpath(os.path.expanduser(cache_dir))
        out.trusted = os.path.realpath(os.path.expanduser(trusted)) == real
        if not out.trusted:
            raise ConfigError(f"parameter 'gain_table_cache_trusted' names {trusted}, which is not "
                              f"gain_table_cache_dir ({cache_dir}): name the cache folder itself, or leave it empty")
    return out


def check_cache_private(table: Path, trusted: bool) -> None:
    """Refuse a cache folder (if it exists) or cached table (if it exists) that another user owns
    or group/others may write (ssh's rule for its keys): anyone who can write there can plant a
    table with a valid checksum. Symlinks are followed: every link on the way must be ours (or
    root's) in a folder others cannot write (unless sticky), and the folder that finally holds the
    table must be private too (whoever may write it may replace the file); a target that is not a
    regular file is refused as such. Checked before the cache is read or written, so a shared folder
    is refused at the first start, not only at the second. ``trusted`` (the folder named by
    ``gain_table_cache_trusted``) skips the check. A link that leads nowhere (dangling, or a loop)
    is left to the save, which replaces it or says why it cannot."""
    if trusted:
        return
    hint = (f"; or set gain_table_cache_trusted:={table.parent} to trust it, or gain_table to a table of "
            "your own")
    for path, what in ((table.parent, "gain_table_cache_dir"), (table, "cached gain table")):
        if not os.path.lexists(path):
            continue
        real = _follow_links(path, what, hint)
        if real is None or not real.exists():
            continue
        via = f" (a symlink to {real})" if real != Path(os.path.abspath(path)) else ""
        if path is table:
            mode = os.stat(real).st_mode
            if not stat.S_ISREG(mode):
                raise ConfigError(f"{what} {path} is {kind_of(mode)}{via}, not a regular file: remove it, or set "
                                  "gain_table to a table of your own")
            check_private(real.parent, f"the folder {real.parent} holding {what} {path}{via} is", exc=ConfigError,
                          hint=hint, named=False)
        check_private(real, f"{what} {path}{via} is", exc=ConfigError, hint=hint, named=False)


def _follow_links(path: Path, what: str, hint: str) -> Path | None:
    """The path that ``path``'s symlinks lead to; :class:`ConfigError` for a link that another user
    owns or that lies in a folder group or others may write (not sticky: they could replace it).
    None for a loop (left to the save)."""
    me = os.geteuid()
    p = Path(os.path.abspath(path))
    for _ in range(40):
        st = os.lstat(p)
        if not stat.S_ISLNK(st.st_mode):
            return p
        folder = os.stat(p.parent)
        if st.st_uid not in (me, 0):
            raise ConfigError(f"{what} {path}: symlink {p} is owned by another user (uid {st.st_uid}), so where it "
                              f"leads cannot be trusted{hint}")
        if folder.st_mode & (stat.S_IWGRP | stat.S_IWOTH) and not folder.st_mode & stat.S_ISVTX:
            raise ConfigError(f"bad permissions: {what} {path}: symlink {p} is in {p.parent}, which group and others "
                              f"may write (mode {stat.S_IMODE(folder.st_mode):04o}), so where it leads cannot be "
                              f"trusted; chmod go-w {p.parent}{hint}")
        p = Path(os.path.abspath(p.parent / os.readlink(p)))
    return None
