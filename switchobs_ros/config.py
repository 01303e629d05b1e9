"""The estimator's configuration: its declared parameters, the params-file reader, and the typed
:class:`EstimatorConfig` that checks every value in one place.

One configuration for every way the estimator runs: the node reads its parameters from rclpy
(:func:`~switchobs_ros.params.declare_all`), the offline bag estimator from params files
(:func:`params_from_file`, the same names, types and errors); both become an
:class:`EstimatorConfig` (:meth:`EstimatorConfig.from_values`), which turns the values into core
objects (system, schedule, noise model) and refuses a bad one with a single
:class:`~switchobs_ros.params.ConfigError` line. :class:`~switchobs_ros.pipeline.EstimatorPipeline`
takes it from there (gain table, observer).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import msg_bridge as mb
from msg_bridge import InputSpecs, SpecError, load_inputs
from switchobs_core.exceptions import InvalidArgument
from switchobs_core.loading import load_yaml
from switchobs_core.model.disturbance import Disturbance
from switchobs_core.model.frames import FrameTransform, parse_transforms
from switchobs_core.model.noise import NoiseModel
from switchobs_core.model.schedule import Cycle
from switchobs_core.model.system import LTISystem
from switchobs_core.ranges import RANGES, check_range
from switchobs_core.runtime.bound_option import BOUND_FORMS
from switchobs_core.runtime.observer import MODES
from switchobs_core.table.ahead import TableReadAhead
from switchobs_core.table.gains import GainTable

from .core_config import (
    GAIN_FAMILY_PARAM,
    cache_dir_param,
    cycles_from_params,
    disturbance_from_params,
    load_system_param,
    noise_from_params,
)
from .params import ConfigError, Param
from .params_files import matching_sections, unmatched_files

__all__ = ["CONSISTENCY", "PARAMS", "UNCHECKED", "EstimatorConfig", "body_frame_prefix", "params_from_file"]

#: Values of the ``consistency.check`` parameter (switchobs_ros.screening): ``auto`` and ``always`` test every
#: sample while a bound is published, ``never`` does not.
CONSISTENCY = ("auto", "always", "never")

#: The start-up warning of ``consistency.check: never``.
UNCHECKED = "consistency.check is 'never': the published bounds are not tested against the data"

#: The estimator node's parameters (the documentation's parameter reference is generated from it: tools/docs_gen.py).
PARAMS = [
    Param("system", "paper", "The system: a built-in scenario name (paper, camera_agents) or a path to a "
          "system YAML file."),
    Param("gain_table", "", "Path of the gain table (JSON or .npz, from `switchobs design`). Empty: use a cached "
          "table for this system/schedule/delta, or design one at start-up and write it to gain_table_cache_dir."),
    Param("gain_table_cache_dir", "~/.cache/switchobs", "Folder for gain tables designed at start-up. A cached "
          "table is used only if the folder and the file are private (owned by this user, not writable by group or "
          "others), and after its gains are re-verified."),
    Param("gain_table_cache_trusted", "", "The cache folder to trust even when it is not private (e.g. a folder "
          "shared by a group): the same path as gain_table_cache_dir ('' trusts none). The gains are re-verified "
          "all the same."),
    Param("delta", 0.99, "Contraction target delta of the design (used only when designing at start-up)."),
    Param("gain_family", "", "Gain family: '' (the table's: lmi or kalman), 'kalman-online' (the Riccati recursion "
          "online, any schedule), or, when designing at start-up, 'lmi' (the paper's gains) or 'kalman' (offline "
          "periodic Kalman gains; needs rate)."),
    Param("rate", 0.0, "Nominal sample rate in Hz: needed to design a kalman table at start-up (0: not set)."),
    Param("noise.measurement_std", -1.0, "Measurement noise std on every output row (m) for the covariance and the "
          "Kalman families (< 0: the system's noise: section, or 1 mm)."),
    Param("noise.process_std", -1.0, "Process noise q on every state, intensity q^2 I (< 0: the system's noise: "
          "section, or 0.01)."),
    Param("noise.max", -1.0, "A declared bound |v| <= noise.max (m) on every measurement row; 0 declares noise-free "
          "samples (< 0: none declared). With it ~/envelope gets a last element noise_bound, a guarantee under any "
          "noise within the bound; without it exact_bound is the noise-free bound (a guarantee only for noise-free "
          "measurements) and the consistency test holds every sample to it: noise withdraws the bounds at the first "
          "sample the bound cannot explain."),
    Param("disturbance.max", (), "Bounds |w_j| <= max_j (m/s^2 for the built-in scenarios' unit accelerations on every "
          "velocity state; one value for all or one per column of the system's disturbance B_w) of a bounded unknown "
          "input x' = A x + B_w w: noise_bound then holds for every such input (needs noise.max), and a Kalman table "
          "designed at start-up takes Q_c = B_w diag(max^2) B_w' (empty: the system's disturbance: section, or none).",
          float),
    Param("bound", "ellipsoid", "Form of the rigorous bounds: 'ellipsoid' (default) or, for a Kalman table, 'phase': "
          "scalars in a norm fixed per phase of the table's periodic grid (3-4x cheaper per sample at n = 12-36, "
          "10x at n = 132; the exact bound about 3x looser, 8x at n = 132, the noise bound 6-27x; its constants "
          "are proved at start-up, about 8 s at n = 132; no declared disturbance). Off the grid the ellipsoids "
          "take over, converted with a proof (stamps jittered within the table's tolerance stay on the scalars)."),
    Param("publish_covariance", True, "Publish ~/covariance and fill the odometry covariances from the error "
          "covariance P (for the LMI family P is propagated under the noise model: about n^3 flops per sample)."),
    Param("schedule.mode", "periodic", "periodic (one cycle), sequence (cycles repeated in order) or robust "
          "(the table's residence-time-box design; needs schedule.h_min/h_max to design)."),
    Param("schedule.tau", (2.0,), "Cycle lengths tau_k in seconds (two-channel systems).", float),
    Param("schedule.s", (0.6,), "Duty fractions s_k = h_1/tau_k, one per schedule.tau entry.", float),
    Param("schedule.h", (), "N-channel cycles: N active times per cycle, cycles concatenated "
          "(overrides schedule.tau/s when set).", float),
    Param("schedule.dead_time", 0.0, "Seconds after each switch while the camera turns (only camera/pose "
          "arrives): the gains are designed with these blind intervals; camera poses in them are used at once."),
    Param("schedule.h_min", 0.0, "Robust mode: shortest residence time h_min of assumption A2 (s)."),
    Param("schedule.h_max", 0.0, "Robust mode: longest residence time h_max of assumption A2 (s)."),
    Param("initial_estimate", (), "Initial estimate x_hat(t0), n values in state order (empty: zeros).", float),
    Param("e0", 1.0, "Bound on the initial error ||x_hat(t0) - x(t0)|| used by the envelopes and the exact bound. "
          "-1: not known; no bound until a window of one switching cycle of consistent data certifies one "
          "(needs noise.max; consistency.recertify)."),
    Param("world_frame", "map", "frame_id of the published odometry (and of the expected input poses)."),
    Param("input_frame_id", "map", "Expected header.frame_id of camera/pose and target/pose ('' accepts any)."),
    Param("input_transforms", (), "Fixed transforms into input_frame_id of the frames inputs may come in, one per "
          "frame: '<frame> x y z yaw pitch roll' (radians) or '<frame> x y z qx qy qz qw', as "
          "static_transform_publisher --frame-id <input_frame_id> --child-frame-id <frame> would broadcast. A "
          "position (and orientation) in such a frame is mapped before it is checked and used.", str),
    Param("body_frames", (), "child_frame_id of each body's odometry, in body order (empty: the body names "
          "camera, agent1, ...).", str),
    Param("frame_prefix", "auto", "Prefix of every body frame id (child_frame_id of the odometry): 'auto' derives it "
          "from the node's namespace (/robot1 -> robot1/agent1; none at the root), '' none, any other value is "
          "used as is (e.g. 'robot1/'). One estimator per robot of a fleet then publishes frames of its own."),
    Param("camera_body", "camera", "Name of the camera body in the system's state and output labels."),
    Param("inputs", "", "Path of a YAML file with an `inputs:` section (topics, message types, fields -> output "
          "rows, channel topic) that overrides the system's (''). Default: the system file's `inputs:` section, "
          "or the paper interface (camera/pose, target/pose, camera/active_channel) for camera/target systems."),
    Param("reorder_window_ms", 50.0, "Milliseconds a sample of a topic shared by several channels waits for its "
          "channel to be certain (a channel message sent after it) before the latest channel sent before it is "
          "taken; DDS reorders topics under load (and stalls a reader for up to 200 ms, bench/RESULTS.md). A "
          "publisher that sends the channel every tick makes samples certain as the next one arrives: with exact "
          "stamps (clock_tolerance_ms 0) at once when it follows the tick's poses (camera_sim, but on a switching "
          "tick), one tick later when it precedes them; one that sends it only on change makes them "
          "wait the whole window. 0: the latest channel received (arrival order)."),
    Param("clock_tolerance_ms", 0.0, "The largest error of any source's stamps against the estimator's clock (ms; "
          "clocks of several computers: their synchronisation's budget, chrony or PTP). It enters the bounds: a stamp "
          "error d is a measurement error of at most sup_{|s|<=d} ||C (e^{A s} - I) x|| "
          "(switchobs_core.bounds.stamp); a sample stamped within it of a switching instant is ambiguous; a stamp "
          "that proves a larger offset (ahead of the receive clock by more) withdraws the bounds. 0: exact stamps."),
    Param("switch_horizon", 0.9, "With the stamped channel: a sample stamped within this fraction of its channel's "
          "shortest designed residence after the latest switching instant (less clock_tolerance_ms) is certain at "
          "once, answered without waiting for a later channel message; the rest of the residence waits for one "
          "(camera_sim sends it right after the tick's poses). A switch that comes sooner than this withdraws the "
          "bounds (switchobs_ros.switching). 0.9 leaves a tenth of the residence for a camera that switches early; "
          "1 trusts the schedule's residences to the nanosecond and answers every sample at once."),
    Param("channel_type", "auto", "The channel topic's message type: switchobs_msgs/msg/ActiveChannel (the "
          "switching instant in its stamp: samples attributed by their stamps), std_msgs/msg/UInt8 (attributed by "
          "the publishers' source timestamps; for one publisher of the channel and the samples), or auto (the type "
          "the channel's publishers offer in the ROS graph)."),
    Param("consistency.chi2_alpha", 0.0, "With noise and no declared bound: a chi-square gate on each sample's "
          "normalised innovation nu' (C P C' + R)^-1 nu; a sample above chi2.ppf(1 - alpha, rows) is rejected "
          "(outlier) and counted. alpha is the gate's false-alarm rate per sample when the noise model holds "
          "(0: off; in [0, 0.5]). Needs a covariance (publish_covariance, or the Kalman families)."),
    Param("consistency.check", "auto", "Test every sample's innovation against the published bound before it is "
          "used (a sample the bound cannot explain proves the model broken: re-attributed when exactly one channel "
          "explains it, else rejected and every bound withdrawn): auto and always (the same) test whenever a bound "
          "is published: against noise_bound with noise.max, else against exact_bound as noise-free samples; never "
          "publishes bounds that nothing checks (a warning at start-up)."),
    Param("consistency.recertify", True, "After a withdrawal (and with e0 = -1 at start-up), certify the bounds "
          "again from a window of one switching cycle of data: a least-squares fit whose radius holds for every "
          "noise within noise.max, rounding included (needs noise.max). Labelled re-certified in diagnostics and "
          "in ~/error_bounds."),
    Param("consistency.bias", True, "A CUSUM per output row on the normalised innovations: a persistent bias beyond "
          "the noise model (about 2 samples of delay for 5 sigma) withdraws the bounds (needs noise.max or a "
          "covariance)."),
    Param("consistency.reinit", True, "When the chi-square gate rejects 25 consecutive samples of one channel (a "
          "model failure of the body only it sees, not outliers), re-initialise that body's states from its "
          "last samples instead of coasting; the bounds are withdrawn (re-certification brings them back)."),
    Param("sensor_timeout", 0.5, "Seconds without an accepted measurement after which diagnostics turn WARN. "
          "Changeable at run time."),
    Param("future_tolerance", 0.5, "Seconds a stamp may lie ahead of the node clock before it is rejected. "
          "Changeable at run time."),
    Param("max_abs_value", 1.0e6, "Largest accepted |coordinate| of an input pose (m). At most 1e50 (a sample enters "
          "the state, whose bounds square it: larger ones could overflow the exact step). Changeable at run time."),
    Param("pairing_timeout", 0.2, "Seconds (wall) to wait for the other half of a camera/target pair before "
          "using one half alone. Changeable at run time."),
    Param("diagnostics_period", 1.0, "Period of /diagnostics in seconds (node clock). Changeable at run time."),
    Param("output.envelope_every", 1, "Publish ~/envelope for every k-th estimate (0: never; ~/state is always "
          "published). Changeable at run time."),
    Param("output.odometry_every", 1, "Publish the bodies' odometry for every k-th estimate (0: never). "
          "Changeable at run time."),
    Param("output.covariance_every", 1, "Publish ~/covariance for every k-th estimate (0: never; needs "
          "publish_covariance). Changeable at run time."),
    Param("output.typed_every", 1, "Publish the typed ~/state_estimate (switchobs_msgs/StateEstimate) and "
          "~/error_bounds (ErrorBounds) for every k-th estimate (0: never). Changeable at run time."),
    Param("output.markers_every", 10, "Publish ~/markers (visualization_msgs/MarkerArray for RViz: each body's "
          "position, 2-sigma ellipse, the guaranteed bound, the body in view) for every k-th estimate (0: never). "
          "Changeable at run time."),
    Param("gc_freeze", True, "Call gc.freeze() once the node is built (start-up objects leave the garbage "
          "collector's generations, see bench/RESULTS.md)."),
    Param("autostart", True, "Managed (lifecycle) node only: configure and activate at start-up (today's "
          "behaviour); false waits for the lifecycle services."),
]

#: Largest output decimation ``output.*_every`` (an int64 parameter; beyond it nothing is ever published).
MAX_EVERY = 1_000_000_000

#: The channel topic's message types (parameter channel_type).
CHANNEL_TYPES = ("auto", "switchobs_msgs/msg/ActiveChannel", "std_msgs/msg/UInt8")


#: Parameters that can change while the node runs (the others need a restart: they shape the
#: observer, its gain table or the topics), and the check of a value: (ok, what it must be). The
#: one owner of both: the start-up check and the on-set-parameters callback use it.
def _ranged(name: str, unit: str = " s"):
    """A runtime parameter's check: its range in :data:`switchobs_core.ranges.RANGES`."""
    lo, hi, lo_open, why = RANGES[name]
    return (lambda v: math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi,
            f"in {'(' if lo_open else '['}{lo:g}, {hi:g}]{unit} ({why})")


RUNTIME_PARAMS = {
    "sensor_timeout": _ranged("sensor_timeout"),
    "future_tolerance": _ranged("future_tolerance"),
    "max_abs_value": _ranged("max_abs_value", ""),
    "pairing_timeout": _ranged("pairing_timeout"),
    "diagnostics_period": _ranged("diagnostics_period"),
    "output.envelope_every": (lambda v: 0 <= v <= MAX_EVERY, f"an integer in [0, {MAX_EVERY}]"),
    "output.odometry_every": (lambda v: 0 <= v <= MAX_EVERY, f"an integer in [0, {MAX_EVERY}]"),
    "output.covariance_every": (lambda v: 0 <= v <= MAX_EVERY, f"an integer in [0, {MAX_EVERY}]"),
    "output.typed_every": (lambda v: 0 <= v <= MAX_EVERY, f"an integer in [0, {MAX_EVERY}]"),
    "output.markers_every": (lambda v: 0 <= v <= MAX_EVERY, f"an integer in [0, {MAX_EVERY}]"),
}


def check_runtime_value(name: str, value: Any) -> str:
    """'' if ``value`` is acceptable for runtime parameter ``name``, else the reason (one line)."""
    if name not in RUNTIME_PARAMS:
        return (f"parameter '{name}' cannot change while the node runs (it shapes the observer, the gain table "
                f"or the topics); restart the node with the new value. Changeable: {', '.join(RUNTIME_PARAMS)}")
    ok, what = RUNTIME_PARAMS[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not ok(value):
        return f"parameter '{name}' must be {what}; got {value!r}"
    return ""


def body_frame_prefix(value: str, namespace: str) -> str:
    """The prefix of the body frame ids for parameter ``frame_prefix`` = ``value`` in ``namespace``:
    ``auto`` gives ``robot1/`` in ``/robot1`` (``fleet/robot1/`` in ``/fleet/robot1``, '' at the root)."""
    if value != "auto":
        return value
    ns = namespace.strip("/")
    return f"{ns}/" if ns else ""


def params_from_file(params_files: Sequence[str | Path] = (), overrides: dict | None = None,
                     node_name: str = "estimator") -> dict:
    """The estimator's parameter values: defaults, then params files (ROS 2 YAML), then overrides.

    A params file is ``<node key>: ros__parameters: {...}``; the sections whose keys match the
    node ``node_name`` (a fully qualified name, or a name at the root) apply as rcl applies them
    (:mod:`switchobs_ros.params_files`: ``/**``, ``/**/estimator``, ``estimator``), nested keys joined
    with ``.`` (``schedule: {mode: ...}`` is ``schedule.mode``). Unknown names, values of the wrong
    type, or a file with no section for the node raise :class:`~switchobs_ros.params.ConfigError`,
    as the node does.
    """
    known = {p.name: p for p in PARAMS}
    cfg = {p.name: p.default for p in PARAMS}
    fqn = node_name if node_name.startswith("/") else "/" + node_name

    def flat(d, prefix=""):
        for k, v in d.items():
            if isinstance(v, dict):
                yield from flat(v, f"{prefix}{k}.")
            else:
                yield f"{prefix}{k}", v

    def num(v, is_float):
        # ROS reads 1.0e6 as a double; YAML 1.1 (PyYAML) reads it as a string
        if is_float and isinstance(v, str):
            try:
                return float(v)
            except ValueError:
                return v
        if is_float and isinstance(v, int) and not isinstance(v, bool):
            return float(v)
        return v

    def put(name, v, where):
        if name in ("use_sim_time",):
            return
        if name not in known:
            raise ConfigError(f"{where}: unknown estimator parameter '{name}' (known: {', '.join(sorted(known))})")
        d = known[name].default
        if isinstance(d, tuple):
            item = known[name].item or (type(d[0]) if d else float)
            if item is float and isinstance(num(v, True), float):
                v = [v]         # one number for a list of doubles: as the node takes it (params.py)
            if not isinstance(v, (list, tuple)):
                raise ConfigError(f"{where}: parameter '{name}' must be a list")
            v = tuple(num(x, item is float) for x in v)
            if d and not v:
                raise ConfigError(f"{where}: parameter '{name}' is empty; give at least one value, or leave it out "
                                  f"for the default {list(d)}")
        elif isinstance(d, float):
            v = num(v, True)
        elif isinstance(d, str) and v is None:
            v = ""
        if not isinstance(d, tuple) and type(v) is not type(d):
            raise ConfigError(f"{where}: parameter '{name}' must be a {type(d).__name__}; got {v!r}")
        cfg[name] = v

    for f in params_files:
        try:
            doc = load_yaml(f, exc=ConfigError, what="params file") or {}
        except FileNotFoundError:
            raise ConfigError(f"params file {f} does not exist") from None
        sections = matching_sections(doc, fqn)
        if not sections:
            raise ConfigError(unmatched_files([f], fqn))
        for sect in sections:
            for name, v in flat(sect):
                put(name, v, f"params file {f}")
    for name, v in (overrides or {}).items():
        put(name, v, "parameter override")
    return cfg


@dataclass(frozen=True)
class EstimatorConfig:
    """The estimator's checked configuration: the raw parameter ``values`` and the core objects
    made from them. Build it with :meth:`from_values` (or :meth:`from_files`)."""

    values: dict
    system: LTISystem
    mode: str
    cycles: tuple[Cycle, ...]
    robust: tuple[float, float] | None
    x0: np.ndarray
    inputs: InputSpecs
    family: str
    noise: NoiseModel
    noise_max: float | None
    rate: float
    publish_covariance: bool
    child_frames: tuple[str, ...]
    transforms: dict[str, FrameTransform] | None = None     # input_transforms by frame
    disturbance: Disturbance | None = None      # disturbance.max (switchobs_core.model.disturbance)
    #: ``gain_table``'s file, read while the system was built (taken by the pipeline's table load)
    table_ahead: TableReadAhead | None = field(default=None, compare=False, repr=False)

    @property
    def e0(self) -> float | None:
        """The initial error bound for the observer (None: ``e0`` is -1, not known)."""
        return None if self.values["e0"] == -1.0 else float(self.values["e0"])

    def __getitem__(self, name: str) -> Any:
        """The raw value of parameter ``name``."""
        return self.values[name]

    @classmethod
    def from_files(cls, params_files: Sequence[str | Path] = (), overrides: dict | None = None) -> EstimatorConfig:
        """Defaults, then params files, then overrides (:func:`params_from_file`), checked."""
        return cls.from_values(params_from_file(params_files, overrides))

    @classmethod
    def from_values(cls, cfg: dict) -> EstimatorConfig:
        """Check every parameter value (names of :data:`PARAMS`) and build the core objects.

        Raises :class:`~switchobs_ros.params.ConfigError` with one line on any bad value.
        """
        values = {p.name: p.default for p in PARAMS}
        values.update(cfg)
        values["gain_table_cache_dir"] = cache_dir_param(values["gain_table_cache_dir"],
                                                         values["gain_table_cache_trusted"])
        path = values["gain_table"]
        # the table file is read in a worker thread while the system (its decompositions) is built
        ahead = TableReadAhead(GainTable, os.path.expanduser(path)) if path and isinstance(path, str) else None
        try:
            return cls._checked(values, ahead)
        except BaseException:
            if ahead is not None:
                ahead.close()       # a refused configuration leaves no thread reading
            raise

    @classmethod
    def _checked(cls, values: dict, ahead: TableReadAhead | None) -> EstimatorConfig:
        """:meth:`from_values` once the defaults are in and ``gain_table``'s file is being read."""
        sys_ = load_system_param(values["system"])
        mode = values["schedule.mode"]
        if mode not in MODES:
            raise ConfigError(f"parameter 'schedule.mode' must be one of {', '.join(MODES)}; got '{mode}'")
        robust = None
        if mode == "robust":
            hmin, hmax = values["schedule.h_min"], values["schedule.h_max"]
            if not 0 < hmin <= hmax:
                raise ConfigError(f"robust mode needs 0 < schedule.h_min <= schedule.h_max; got {hmin}, {hmax}")
            robust = (hmin, hmax)
            cycles = []
            if values["schedule.dead_time"]:
                raise ConfigError("parameter 'schedule.dead_time' needs a known schedule (periodic or sequence): "
                                  "the robust design has no cycles to place the blind intervals in")
        else:
            cycles = cycles_from_params(mode, values["schedule.tau"], values["schedule.s"], values["schedule.h"],
                                        sys_.N, values["schedule.dead_time"])
        v = values["delta"]             # the runtime parameters: check_runtime_value below
        if not (math.isfinite(v) and v > 0):
            raise ConfigError(f"parameter 'delta' must be a finite number > 0; got {v}")
        if values["e0"] != -1.0:       # -1: not known (no bound until the data certify one)
            check_range(values["e0"], "e0", exc=ConfigError)
        for v in values["initial_estimate"]:
            check_range(v, "initial_estimate", exc=ConfigError)
        x0 = values["initial_estimate"]
        if x0 and len(x0) != sys_.n:
            raise ConfigError(f"parameter 'initial_estimate' has {len(x0)} values; the system has n = {sys_.n} "
                              f"states ({', '.join(sys_.state_labels)})")
        x0 = np.array(x0, dtype=float) if x0 else np.zeros(sys_.n)
        try:
            inputs = load_inputs(values["system"], sys_, camera_body=values["camera_body"], override=values["inputs"])
        except SpecError as err:
            raise ConfigError(f"input specification: {err}") from None
        if values["consistency.check"] not in CONSISTENCY:
            raise ConfigError(f"parameter 'consistency.check' must be one of {', '.join(CONSISTENCY)}; "
                              f"got {values['consistency.check']!r}")
        check_range(values["reorder_window_ms"], "reorder_window_ms", exc=ConfigError)
        check_range(values["clock_tolerance_ms"], "clock_tolerance_ms", exc=ConfigError)
        check_range(values["switch_horizon"], "switch_horizon", exc=ConfigError)
        if values["channel_type"] not in CHANNEL_TYPES:
            raise ConfigError(f"parameter 'channel_type' must be one of {', '.join(CHANNEL_TYPES)}; got "
                              f"'{values['channel_type']}'")
        check_range(values["consistency.chi2_alpha"], "consistency.chi2_alpha", exc=ConfigError)
        family = values["gain_family"]
        if family not in GAIN_FAMILY_PARAM:
            raise ConfigError(f"parameter 'gain_family' must be one of {', '.join(map(repr, GAIN_FAMILY_PARAM))}; "
                              f"got {family!r}")
        rate = check_range(values["rate"], "rate", exc=ConfigError)
        dist = disturbance_from_params(values, sys_)
        noise = noise_from_params(values, sys_, dist)
        for name in RUNTIME_PARAMS:
            why = check_runtime_value(name, values[name])
            if why:
                raise ConfigError(why)
        if not values["world_frame"]:
            raise ConfigError("parameter 'world_frame' must not be empty (the frame_id of the published odometry)")
        vmax = check_range(values["noise.max"], "noise.max", exc=ConfigError)
        if values["bound"] not in BOUND_FORMS:
            raise ConfigError(f"parameter 'bound' must be one of {', '.join(BOUND_FORMS)}; got {values['bound']!r}")
        if dist is not None and dist.active and vmax < 0:
            raise ConfigError("parameter 'disturbance.max' declares a disturbance, which enters noise_bound: declare "
                              "noise.max too (0: noise-free samples)")
        bodies = [b.name for b in mb.bodies(sys_.state_labels)]
        frames = values["body_frames"]
        if frames and len(frames) != len(bodies):
            raise ConfigError(f"parameter 'body_frames' has {len(frames)} names for {len(bodies)} bodies "
                              f"({', '.join(bodies)})")
        if values["frame_prefix"].startswith("/"):
            raise ConfigError(f"parameter 'frame_prefix' must not start with '/' (tf2 frame ids do not); got "
                              f"{values['frame_prefix']!r}")
        try:
            transforms = parse_transforms(values["input_transforms"], values["input_frame_id"])
        except InvalidArgument as err:
            raise ConfigError(f"parameter 'input_transforms': {err}") from None
        return cls(values=values, system=sys_, mode=mode, cycles=tuple(cycles), robust=robust, x0=x0,
                   inputs=inputs, family=family, noise=noise, noise_max=vmax if vmax >= 0 else None, rate=rate,
                   publish_covariance=bool(values["publish_covariance"]),
                   child_frames=tuple(frames) if frames else tuple(bodies), transforms=transforms,
                   disturbance=dist if dist is not None and dist.active else None, table_ahead=ahead)
