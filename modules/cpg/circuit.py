"""MLMP-CPG circuits as data: a YAML file lists the joints, their synaptic tables, the RG-RG couplings,
the sensory neurons and the joint command; this module validates it.

A circuit file is checked like a scenario: frozen models, unknown keys rejected, strict types (a
string is not a number), finite numbers, and every name it refers to (sensory neuron, input, joint,
``joint.E``/``joint.F`` neuron) must exist. Problems are reported as
``FILE: key.path: expected ..., got ... (did you mean ...?)`` with ``sfl_brain.scenario.Problem``.

Layout of a file (see ``circuits/*.yaml``; CPG-HUMANOID.md is "the digest" below)::

    name: ...
    command: voltage | position        # (3.6) V = M (G_E U_E + G_F U_F) with G_E = 1, G_F = -1,
                                       # or theta_0 + G (MN_E - MN_F) (digest §5, §7.8)
    pf_input: potential | bounded      # the RG output the PF reads (4.10): V, or tanh(V / A_f)
    cell: {tau_m, tau_s, A_f, E_s}     # the Rowat-Selverston constants, (4.1)-(4.8)
    motor_neuron: {alpha, theta}       # (4.11): 5 and 0.5, L1127
    inputs: [names of the raw sensor values, in the order of the array given to advance()]
    sensory_neurons: [{name, input, alpha, theta}]       # (4.13)
    joints:
      - name: hip_l
        rg: {sigma_s, sigma_f}          # (4.4)-(4.7); optional sigma_in/sigma_out for (4.8)
        pf: {alpha, theta, alpha_mlr, theta_mlr}          # (4.9)
        rg_mutual: -1                   # Table 4.1: RG-E -> RG-F and RG-F -> RG-E
        synapses: {ES: {MN_E: -0.4}}    # sensory neuron -> {PF_E, PF_F, MN_E, MN_F: weight}
        gain: 1.0                       # M of (3.6) or G of the position command
        theta0: 0.0                     # position command offset, rad
        angle_input: hip_l              # the input holding this joint's angle (pattern switching)
    couplings: [{source: hip_l.E, target: hip_r.F, weight: 1.0}]   # RG -> RG, through tanh(V/A_f)
    kicks: [{joints: [hip_l], start: 0.0, duration: 0.08, amplitude: 1.0}]
    phase_resets: [{sensor: GB_l, joint: hip_l, amplitude: -1.0, duration: 0.04, enabled: true}]
                                       # mode: pulse (as this) or state: {sensor: GB_l, joint: hip_l,
                                       #   mode: state, joints: [hip_l, knee_l, ankle_l], refractory: 0.4, after: 2.0,
                                       #   state: {hip_l: {E: [V, q], F: [V, q]}, ...}} (calibrate.py measures it)
    switches: [{joints: {knee_l: {sigma_s: .., sigma_f: ..}}, at: 2.0}]   # or input: ..., above: ... (a level)
                                       # or input: ..., rate_above: ... (a push detector); inhibit: [[hip_l, knee_l]]
                                       # theta0: continuous | angle; kick_direction: fixed | motion
    start_from_pose: [ankle_pitch_l]   # position circuits: these joints' command equals the measured pose at t = 0
    start_slope: {ankle_pitch_l: -1.0} # position circuits: start pose0 + k slope when a trial gives its slope
    gain_groups: {pitch: [hip_pitch_l, ...], roll: [hip_roll_l, ...]}   # ch. 5's learnt MN gains (w1, w2, L1631): a
                                       # trial's gain_pitch / gain_roll multiply the G of every joint of the group
    posture: {input: torso_pitch, target: 0.1745, gain: 0.1, joints: {ankle_pitch_l: 1, ankle_pitch_r: 1},
              limit: 0.15, window: 0.667, relative_sensors: [FB, FF]}
                                       # position circuits: the torso held near target (L1764): a slow integral
                                       # term on the joints' theta_0, d theta_0 / dt = gain sign (input - target)
    ankle_adaptation: {pitch_input: torso_pitch, feet: {ankle_pitch_l: {heel: GB_l, toe: GF_l, chain: [...]}, ...},
                       rate: .., per_slope_up: .., per_slope_down: .., speed: .., limit: ..}
                                       # position circuits: each ankle's centre follows the slope under its foot
    start_ramp: 2.0                    # s: alpha_MLR grows from 0 over a trial's first seconds

Current pulses (kicks, phase resets, switch kicks) follow the author's code sign convention (digest
§5): ``amplitude`` is the current injected into the flexor RG, the extensor RG receives its negative.
"""

from __future__ import annotations

import copy
import functools
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from sfl_brain.registry import nearest
from sfl_brain.scenario import Problem, ScenarioError, parse_yaml, problems_from

CIRCUITS = Path(__file__).resolve().parent / "circuits"

Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0)]
Positive = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0)]
Name = Annotated[str, Field(strict=True, min_length=1, pattern=r"^[A-Za-z][A-Za-z0-9_]*$")]
Target = Literal["PF_E", "PF_F", "MN_E", "MN_F"]


class Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)


class Cell(Strict):
    """Constants of every rhythm generator cell, (4.1)-(4.8). Times in s, potentials in the model's mV."""

    tau_m: Positive = 0.05  # membrane time constant, s: L1617 ("tau_m = 0.05 ... for all rhythmic neurons")
    tau_s: Positive = 1.0  # slow current time constant, s: L1617
    A_f: Positive = 5.0  # amplitude of the fast current's N-shape (4.4): not in the thesis; author's code (digest §5)
    E_s: Number = 0.0  # reversal potential of the slow current (4.6): not in the thesis; author's code (digest §5)


class MotorNeuronConstants(Strict):
    alpha: Number = 5.0  # slope of (4.11), "fixed empirically to 5", L1127
    theta: Number = 0.5  # threshold of (4.11), "fixed empirically to ... 0.5", L1127


class RhythmGenerator(Strict):
    """The two shape parameters of the RG cell of a joint (both its E and F cells)."""

    sigma_s: NonNegative  # g_K / g_L (4.7); thesis range [0, 5] (Table 4.1)
    sigma_f: NonNegative  # g_Ca / g_L (4.5); thesis range [0, 5] (Table 4.1)
    sigma_in: NonNegative | None = None  # (4.8) inward slow conductance (V < E_s); None: sigma_s
    sigma_out: NonNegative | None = None  # (4.8) outward slow conductance (V > E_s); None: sigma_s


class PatternFormation(Strict):
    """Constants of the joint's two PF neurons (4.9)."""

    alpha: NonNegative  # slope; thesis ]0, 10] (Table 4.1), author's code 0.015-0.022 (digest §5)
    theta: Number = 0.0  # threshold; thesis [-0.5, 0.5] (Table 4.1), author's code 0 (digest §5)
    alpha_mlr: Number = 1.0  # descending slope modulation (4.9); author's code default 1 (digest §5)
    theta_mlr: Number = 0.0  # descending threshold modulation (4.9): +0.5 extensor, -0.5 flexor domination (L1160)


class Joint(Strict):
    """One joint's CPG: RG, PF and MN neurons, extensor (E) and flexor (F), and its synaptic table."""

    name: Name
    rg: RhythmGenerator
    pf: PatternFormation
    rg_mutual: Number = -1.0  # RG-E -> RG-F and RG-F -> RG-E, Table 4.1 (L1349)
    w_rg2pf: Number = 1.0  # (4.10), Table 4.1 (RG-E -> PF-E = 1)
    w_pf2mn: Number = 1.0  # (4.12), Table 4.1 (PF-E -> MN-E = 1)
    synapses: dict[Name, dict[Target, Number]] = {}  # sensory neuron -> {target: weight}
    gain: Number = 1.0  # M of (3.6) (voltage) or G of theta_0 + G (MN_E - MN_F) (position)
    theta0: Number = 0.0  # position command offset, rad
    angle_input: Name | None = None  # input holding this joint's angle (switches, start_from_pose)
    # position circuits: the joint's angle at the start the gain and theta0 were calibrated for (rad; start_slope)
    pose0: Number | None = None


class SensoryNeuron(Strict):
    """(4.13) rho = 1 / (1 + exp(alpha (theta - phi))), phi = the named input."""

    name: Name
    input: Name
    alpha: Number
    theta: Number


class Coupling(Strict):
    """An RG -> RG synapse: ``source``/``target`` are ``joint.E`` or ``joint.F``."""

    source: str
    target: str
    weight: Number


class Kick(Strict):
    """A current pulse at a scheduled time: +amplitude into each joint's RG-F, -amplitude into RG-E."""

    joints: list[Name] = Field(min_length=1)
    start: NonNegative  # s
    duration: Positive  # s
    amplitude: Number


Pair = Annotated[list[Number], Field(min_length=2, max_length=2)]


class CellState(Strict):
    """The state of one joint's two RG cells, each [V, q] (the model's mV, (4.1)-(4.2))."""

    E: Pair
    F: Pair


class PhaseReset(Strict):
    """Phase resetting (thesis L1270-1282, digest §7.10): "the rhythmic neurons were driven by ground contact force
    sensors". When the sensory neuron ``sensor`` rises through ``threshold`` (below it last tick, at or above it now):

    - ``mode: pulse`` (§7.10's first choice): a current pulse into ``joint``'s RG, ``amplitude`` into RG-F (RG-E gets
      its negative) for ``duration`` s. Landing mid-burst it delays the rhythm rather than resetting it;
    - ``mode: state`` (§7.10's alternative): the RGs of ``joints`` (default: ``joint`` alone; a leg's joints, e.g. hip,
      knee and ankle) jump to ``state``, the stance-onset state taken from the unperturbed gait (measured by
      ``python -m sfl_brain.modules.cpg.calibrate stance``): the phase is set, whatever it was.

    Either way once per landing: not within ``refractory`` s of this entry's last reset (a heel bouncing), and not
    before ``after`` s of trial time (the start-up transient). The defaults (pulse, 0, 0) are the behaviour before
    these fields existed."""

    sensor: Name
    joint: Name  # the RG a pulse goes into (a state entry keeps it: a trial may ask for pulses)
    mode: Literal["pulse", "state"] = "pulse"
    amplitude: Number = -1.0  # into RG-F (RG-E gets +1): the sign that starts extension (stance), §7.10
    duration: Positive = 0.04  # s, §7.10
    threshold: Number = 0.5  # GB "rising through 0.5", §7.10
    refractory: NonNegative = 0.0  # s: no second reset of this entry within it (chosen here; not in the thesis)
    after: NonNegative = 0.0  # s of trial time: no reset before it (chosen here; not in the thesis)
    joints: list[Name] | None = None  # the RGs a state reset sets; None = [joint]
    state: dict[Name, CellState] = {}  # joint -> its stance-onset state; needed for every joint of `joints` (state)
    enabled: bool = True

    @property
    def state_joints(self) -> list[str]:
        """The joints whose RGs a state reset sets."""
        return list(self.joints) if self.joints is not None else [self.joint]

    def missing_states(self) -> list[str]:
        """Joints of ``state_joints`` without a stored state (a state reset needs none missing)."""
        return [name for name in self.state_joints if name not in self.state]


class Switch(Strict):
    """Pattern switching (digest §7.11): new (sigma_s, sigma_f) for the named joints, V = q = 0, a position command
    that goes on from the measured angle (``theta0``, below), then a kick of ``kick`` (into RG-F; RG-E gets its
    negative) for ``kick_duration`` s, its sign as given or by the joint's motion (``kick_direction``).

    Triggered once: at time ``at`` (s), or when the input ``input`` exceeds ``above`` (a level), or when its rate of
    change exceeds ``rate_above`` (per s; the push detector of §7.11, e.g. the torso's pitch rate). ``joint_kicks``
    gives a joint its own kick: its sign is the direction of that joint's switch (L1437). ``inhibit`` lists joint
    pairs whose RG-RG couplings (both ways) are silenced at the switch: "synapses between CPGs of the hip and the
    knee joints are inhibited, while keeping the connection between CPGs of the ankle and the hip" (L1311), since
    "inhibiting the synaptic connection between CPGs is necessary to get different patterns in different joints"
    (L1292)."""

    joints: dict[Name, RhythmGenerator] = Field(min_length=1)
    at: NonNegative | None = None
    input: Name | None = None
    above: Number | None = None
    rate_above: Number | None = None
    kick: Number = 1.0  # §7.11 ("kick +-I"), I = 1 as the kicks of §7.1
    kick_duration: Positive = 0.2  # s, §7.11 / §5 (the author's later scripts)
    joint_kicks: dict[Name, Number] = {}
    inhibit: list[Annotated[list[Name], Field(min_length=2, max_length=2)]] = []
    # A position-commanded joint's theta_0 at the switch. "continuous" (the default): theta_0 := angle - G (MN_E - MN_F)
    # with the switch tick's MN, so the command equals the measured angle: the joint goes on from where it is. The
    # thesis switches the RG/PF patterns (L1284-1324, L1430-1437) and says nothing of the command's offset; this
    # changes nothing else. "angle": theta_0 := the measured angle. That rule is not the thesis's: it comes from the
    # author's later (2017) scripts (digest §5, last bullet), whose circuit has its reflexes off; in a circuit with
    # reflexes G (MN_E - MN_F) is not 0 at the switch, and the command jumps by that offset (E4.7,
    # docs/results/chapter4/humanoid.md).
    theta0: Literal["angle", "continuous"] = "continuous"
    # "fixed": each joint's kick as given. "motion" (issue 23's reading of E4.4: each joint kicked in the direction it
    # is moving; "the direction of the switching in each joint is related to the direction of the injected current",
    # L1437): its magnitude as given, its sign such that the RG pushes the joint further the way it moves at the switch
    # (the rate of its angle_input over the last tick; the given sign when it does not move or on the trial's first
    # tick)
    kick_direction: Literal["fixed", "motion"] = "fixed"
    name: Name | None = None  # a label, shown in the switch's event (the controller names its presets so)
    armed: bool = True  # armed at a trial's start (a controller's presets are not: it arms the one a trial chooses)


class Posture(Strict):
    """Keeping the torso at an angle from the vertical (L1764: "The inertial sensor is also used to adjust the center
    of oscillation of ankle joints in order to keep the robot torso close to the vertical with a small inclination in
    the walking sense. For the NAO robot, we keep this angle closed to 10 deg"; digest §7.18): a slow integral term on
    the listed joints' command offsets. Every control tick of dt s

        shift_j += gain * sign_j * (input - target) * dt,   clipped to [-limit, +limit];   theta_0,j = file's + shift_j

    so a torso leaning past ``target`` moves the joints' oscillation centre by ``sign`` until it is back (the thesis
    gives neither the gain nor how the ankles move: chosen here). ``input``: the circuit input holding the angle
    (rad); ``gain``: 1/s (0: off; a trial may set another, ``posture_gain``); ``limit``: rad, the most the offsets
    move either way."""

    input: Name
    target: Number  # rad: L1764's 10 deg is 0.1745
    gain: NonNegative  # 1/s
    joints: dict[Name, Literal[-1, 1]] = Field(min_length=1)  # joint -> the sign of its shift per rad of lean
    limit: Positive  # rad
    # s: the input averaged over this window (one gait cycle: the gait's own swing of the torso averages out, issue
    # 29) before it is compared with the target; 0: the raw input, as before
    window: NonNegative = 0.0
    # sensory neurons whose threshold is moved by ``target`` while the term is on (the fall sensors FB/FF, L1347: a
    # fall back or forward from the held lean, not from the vertical; their thresholds at +-0.1 rad would otherwise sit
    # inside the swing about 10 deg and saturate, issue 29)
    relative_sensors: list[Name] = []


class FootSense(Strict):
    """How one foot senses the ground under it (``AnkleAdaptation``): its heel and toe contact neurons (GB, GF,
    L1345) and the inputs whose sum with the adaptation's ``pitch_input`` is the sole's pitch in the world (rad, about
    the pitch axis: the torso's pitch plus the leg's pitch joints, all turning about the same axis)."""

    heel: Name  # a sensory neuron (GB)
    toe: Name  # a sensory neuron (GF)
    chain: list[Name] = Field(min_length=1)  # inputs, rad


class AnkleAdaptation(Strict):
    """Each ankle's centre of oscillation follows the slope sensed under its own foot (issue 29; L1417: "adjust the
    center of oscillation of each joint" to switch from flat to sloped terrain; L1737: on a slope the ankle pitch is set
    from the stance; L1764: the inertial sensor adjusts the centre of oscillation of the ankles). Every control tick:

        flat stance of foot f (heel and toe neurons >= stance):  g_f = -(pitch_input + sum(chain_f))   (the ground's
            slope under the sole, rad, + = uphill)
                                                            s_f += (g_f - s_f) min(1, rate dt)
        a foot not in flat stance aims at the ground last sensed in flat stance (by either foot: it lands where the
        other stands); the aimed slope is clipped to +-limit;
        centre_f -> per_slope_up s (s > 0) or per_slope_down s (s < 0), at most ``speed`` rad/s;   theta_0,f += the
        change of centre_f.

    At the trial's first tick s_f is the sole's pitch the start pose shows (a ramp start: the ankles take the slope at
    once), so a gait started on a ramp and the same gait reached by walking onto it have the same ankle centres by
    construction. The thesis gives no values: each is chosen or calibrated in the circuit file."""

    pitch_input: Name  # the torso's pitch to the vertical, rad, + = forward (the inertial sensor, L1759)
    feet: dict[Name, FootSense] = Field(min_length=1)  # ankle pitch joint -> its foot
    stance: Number = 0.5  # both contact neurons at or above: the sole flat on the ground (GB/GF > 0.9 in stance, L1345)
    rate: Positive  # 1/s
    per_slope_up: Number  # rad of centre per rad of uphill slope
    per_slope_down: Number  # rad of centre per rad of downhill slope
    speed: Positive  # rad/s
    limit: Positive  # rad: the steepest slope followed
    share: bool = True  # a foot not lying flat aims at the ground last sensed by a foot lying flat
    enabled: bool = False  # on unless a trial says (trial parameter ankle_adaptation)


class Circuit(Strict):
    """A whole MLMP-CPG: what the network is built from."""

    name: Name
    description: str = ""
    command: Literal["voltage", "position"]
    # what the PF reads of its RG (4.10): "potential" = V itself (author's code, digest §5, §7.3: V swings about +-5.5
    # to +-8, so the PF's threshold range [-0.5, 0.5] of Table 4.1 moves it little), "bounded" = tanh(V / A_f), the
    # RG's bounded output that already carries the RG-RG synapses (§7.3), of order 1 like the thesis's PF input
    # (Fig. 4.6: theta_MLR = +-0.5 dominates, L1160)
    pf_input: Literal["potential", "bounded"] = "potential"
    cell: Cell = Cell()
    motor_neuron: MotorNeuronConstants = MotorNeuronConstants()
    inputs: list[Name] = []
    sensory_neurons: list[SensoryNeuron] = []
    joints: list[Joint] = Field(min_length=1)
    couplings: list[Coupling] = []
    kicks: list[Kick] = []
    phase_resets: list[PhaseReset] = []
    switches: list[Switch] = []
    # position circuits (issue 23 item 2, slope-aware starts): at a trial's first tick these joints' theta_0 := their
    # measured angle - G (MN_E - MN_F) with that tick's MN (as a continuous switch), so that their command equals the
    # pose the body starts in (e.g. the humanoid's ankles, pitched by a ramp). Chosen here, not in the thesis.
    start_from_pose: list[Name] = []
    # position circuits (issue 23 item 2): joint -> how its start angle changes per rad of ground slope (the humanoid
    # starts on a ramp with its ankles pitched by -slope). When a trial gives the start's slope (the controller's trial
    # parameter start_slope_deg), at its first tick each listed joint's theta_0 := pose0 + k slope - G (MN_E - MN_F)
    # with that tick's MN: its command is the calibrated start pose shifted by the slope, whatever the start's own
    # noise (which start_from_pose would keep as an offset for the whole trial). Chosen here, not in the thesis.
    start_slope: dict[Name, Number] = {}
    # ch. 5's learnt motor-neuron gains (L1631, Fig. 5.9 caption: "w1 is motor neuron gain in pitch, w2 is motor neuron
    # gain in roll"): the joints of each group, whose gains a trial scales together (trial parameters gain_pitch,
    # gain_roll: multipliers of each joint's own calibrated gain; digest §7.8). A joint is in at most one group.
    gain_groups: dict[Literal["pitch", "roll"], list[Name]] = {}
    # position circuits: the torso held near an angle by the joints' offsets (L1764, digest §7.18; ``Posture``)
    posture: Posture | None = None
    # position circuits: the ankles' centres follow the slope the feet sense (issue 29; ``AnkleAdaptation``)
    ankle_adaptation: AnkleAdaptation | None = None
    # s: the descending slope alpha_MLR (4.9) grows linearly from 0 to its value over a trial's first seconds (the
    # oscillation's amplitude with it, L1419): the walk starts gradually rather than at full amplitude from the kicks.
    # 0: at once (as before). Chosen here (issue 29), not in the thesis
    start_ramp: NonNegative = 0.0

    def joint_index(self, name: str) -> int:
        return [j.name for j in self.joints].index(name)

    def state_reset_problem(self) -> str:
        """Why the phase resets cannot all act as state resets (entries without a stance-onset state for each of
        their joints), or "" when they can (``phase_reset: state``)."""
        lacking = [
            f"phase_resets.{i} {r.missing_states()}" for i, r in enumerate(self.phase_resets) if r.missing_states()
        ]
        if not lacking:
            return ""
        return (
            f"expected a stance-onset state for every joint of every phase reset of circuit {self.name} ('state'); "
            f"none for {', '.join(lacking)}"
        )

    def neuron_index(self, ref: str) -> int:
        """Index of ``joint.E`` / ``joint.F`` in the network's neuron vector (2 j for E, 2 j + 1 for F)."""
        joint, side = ref.split(".")
        return 2 * self.joint_index(joint) + (0 if side == "E" else 1)


# --------------------------------------------------------------------------------------------
# Loading, checking, overriding
# --------------------------------------------------------------------------------------------


def _fields_at(loc: tuple) -> list[str]:
    """Valid keys at ``loc`` in a circuit (list indices and dict keys skipped), for did-you-mean."""
    model: Any = Circuit
    mapping_key = False  # the next part is a key of a dict field (a joint's name), not a field
    for part in loc:
        if not (isinstance(model, type) and issubclass(model, BaseModel)):
            return []
        if isinstance(part, int) or mapping_key:
            mapping_key = False
            continue
        field = model.model_fields.get(str(part))
        if field is None:
            return []
        mapping_key = typing.get_origin(field.annotation) is dict
        model = _inner_model(field.annotation)
        if model is None:
            return []
    return list(model.model_fields) if isinstance(model, type) and issubclass(model, BaseModel) else []


def _inner_model(annotation: Any) -> Any:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()):
        found = _inner_model(arg)
        if found is not None:
            return found
    return None


def _schema_problems(exc: ValidationError) -> list[Problem]:
    problems = problems_from(exc, Circuit)
    out = []
    for err, problem in zip(exc.errors(), problems, strict=False):
        if err["type"] == "extra_forbidden":  # scenario's resolver does not walk lists of models
            loc = tuple(err["loc"])
            valid = _fields_at(loc[:-1])
            message = f"unknown key; expected one of {sorted(valid)}"
            problem = Problem(problem.path, message, nearest(str(loc[-1]), valid))
        out.append(problem)
    return out


def _reference_problems(c: Circuit) -> list[Problem]:
    """Names that must exist: inputs, sensory neurons, joints, ``joint.E``/``joint.F``."""
    out: list[Problem] = []
    joints = [j.name for j in c.joints]
    sensors = [s.name for s in c.sensory_neurons]
    neurons = [f"{j}.{side}" for j in joints for side in ("E", "F")]

    def need(path: str, given: str | None, valid: list[str], what: str) -> None:
        if given is not None and given not in valid:
            out.append(Problem(path, f"expected one of the {what} {valid}; got {given!r}", nearest(given, valid)))

    def unique(path: str, names: list[str], key: str = ".name") -> None:
        seen = set()
        for i, n in enumerate(names):
            if n in seen:
                out.append(Problem(f"{path}.{i}{key}", f"expected a unique name; got {n!r} twice"))
            seen.add(n)

    unique("joints", joints)
    unique("sensory_neurons", sensors)
    if len(set(c.inputs)) != len(c.inputs):
        out.append(Problem("inputs", f"expected unique names; got {c.inputs}"))
    for i, s in enumerate(c.sensory_neurons):
        need(f"sensory_neurons.{i}.input", s.input, c.inputs, "inputs")
    for i, j in enumerate(c.joints):
        for source in j.synapses:
            need(f"joints.{i}.synapses.{source}", source, sensors, "sensory neurons")
        need(f"joints.{i}.angle_input", j.angle_input, c.inputs, "inputs")
        if c.command == "voltage" and j.theta0 != 0.0:
            out.append(Problem(f"joints.{i}.theta0", f"expected 0 for a voltage command; got {j.theta0}"))
    for i, k in enumerate(c.couplings):
        need(f"couplings.{i}.source", k.source, neurons, "RG neurons")
        need(f"couplings.{i}.target", k.target, neurons, "RG neurons")
    for i, k in enumerate(c.kicks):
        for n, name in enumerate(k.joints):
            need(f"kicks.{i}.joints.{n}", name, joints, "joints")
    for i, r in enumerate(c.phase_resets):
        need(f"phase_resets.{i}.sensor", r.sensor, sensors, "sensory neurons")
        need(f"phase_resets.{i}.joint", r.joint, joints, "joints")
        for n, name in enumerate(r.joints or ()):
            need(f"phase_resets.{i}.joints.{n}", name, joints, "joints")
        unique(f"phase_resets.{i}.joints", r.joints or [], key="")
        for name in r.state:
            need(f"phase_resets.{i}.state.{name}", name, r.state_joints, "joints this reset sets")
        if r.mode == "state":
            for name in (name for name in r.missing_states() if name in joints):
                out.append(
                    Problem(
                        f"phase_resets.{i}.state.{name}",
                        "expected the stance-onset state {E: [V, q], F: [V, q]} of every joint in `joints` "
                        "(mode: state); got none",
                    )
                )
    for i, s in enumerate(c.switches):
        for name in s.joints:
            need(f"switches.{i}.joints.{name}", name, joints, "joints")
        for name in s.joint_kicks:
            need(f"switches.{i}.joint_kicks.{name}", name, list(s.joints), "joints this switch switches")
        for n, pair in enumerate(s.inhibit):
            for m, name in enumerate(pair):
                need(f"switches.{i}.inhibit.{n}.{m}", name, joints, "joints")
        levels = [key for key in ("above", "rate_above") if getattr(s, key) is not None]
        if (s.at is None) == (s.input is None):
            out.append(Problem(f"switches.{i}", "expected exactly one trigger, `at` or `input`; got both or neither"))
        if s.input is not None:
            need(f"switches.{i}.input", s.input, c.inputs, "inputs")
            if len(levels) != 1:
                out.append(
                    Problem(f"switches.{i}", f"expected one of `above`, `rate_above` with `input`; got {levels}")
                )
        elif levels:
            out.append(Problem(f"switches.{i}.{levels[0]}", "expected only with `input`"))
        if s.kick_direction == "motion":
            for name in s.joints:
                if name in joints and c.joints[joints.index(name)].angle_input is None:
                    out.append(
                        Problem(
                            f"switches.{i}.joints.{name}",
                            f"expected a joint with an `angle_input` (kick_direction: motion reads its rate); {name!r} "
                            "has none",
                        )
                    )
    for n, name in enumerate(c.start_from_pose):
        path = f"start_from_pose.{n}"
        if c.command != "position":
            out.append(Problem(path, f"expected no joints for a {c.command} command (position circuits only)"))
            break
        need(path, name, joints, "joints")
        if name in joints and c.joints[joints.index(name)].angle_input is None:
            out.append(Problem(path, f"expected a joint with an `angle_input` (its measured pose); {name!r} has none"))
    unique("start_from_pose", list(c.start_from_pose), key="")
    for name in c.start_slope:
        path = f"start_slope.{name}"
        if c.command != "position":
            out.append(Problem(path, f"expected no joints for a {c.command} command (position circuits only)"))
            break
        need(path, name, joints, "joints")
        if name in joints and c.joints[joints.index(name)].pose0 is None:
            out.append(Problem(path, f"expected a joint with a `pose0` (its calibrated start pose); {name!r} has none"))
    owner: dict[str, str] = {}
    for group, members in c.gain_groups.items():
        for n, name in enumerate(members):
            path = f"gain_groups.{group}.{n}"
            need(path, name, joints, "joints")
            if name in owner:
                where = "twice in this group" if owner[name] == group else f"already in group {owner[name]!r}"
                out.append(Problem(path, f"expected a joint in at most one gain group; got {name!r} {where}"))
            owner.setdefault(name, group)
    if c.posture is not None:
        if c.command != "position":
            out.append(Problem("posture", f"expected none for a {c.command} command (position circuits only)"))
        need("posture.input", c.posture.input, c.inputs, "inputs")
        for name in c.posture.joints:
            need(f"posture.joints.{name}", name, joints, "joints")
        for n, name in enumerate(c.posture.relative_sensors):
            need(f"posture.relative_sensors.{n}", name, sensors, "sensory neurons")
    adaptation = c.ankle_adaptation
    if adaptation is not None:
        if c.command != "position":
            out.append(Problem("ankle_adaptation", f"expected none for a {c.command} command (position circuits only)"))
        need("ankle_adaptation.pitch_input", adaptation.pitch_input, c.inputs, "inputs")
        for name, foot in adaptation.feet.items():
            need(f"ankle_adaptation.feet.{name}", name, joints, "joints")
            need(f"ankle_adaptation.feet.{name}.heel", foot.heel, sensors, "sensory neurons")
            need(f"ankle_adaptation.feet.{name}.toe", foot.toe, sensors, "sensory neurons")
            for n, source in enumerate(foot.chain):
                need(f"ankle_adaptation.feet.{name}.chain.{n}", source, c.inputs, "inputs")
    return out


def validate_circuit(data: Any, file: str = "<circuit>") -> Circuit:
    """Check a circuit given as plain data (a dict as read from YAML); raise ``ScenarioError`` listing every problem."""
    if not isinstance(data, dict):
        raise ScenarioError(file, [Problem("", f"expected a mapping; got {type(data).__name__}")])
    try:
        circuit = Circuit.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(file, _schema_problems(exc)) from None
    problems = _reference_problems(circuit)
    if problems:
        raise ScenarioError(file, problems)
    return circuit


def circuit_path(name_or_path: str | Path) -> Path:
    """A shipped circuit by name (``planar_8link``) or any YAML file by path."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        return path
    return CIRCUITS / f"{name_or_path}.yaml"


def read_circuit_data(name_or_path: str | Path) -> dict:
    """The circuit file's raw data, unvalidated (to apply overrides to): a fresh copy on every call.

    Read with the scenario's YAML loader (``sfl_brain.scenario.parse_yaml``: the same limits for files from
    strangers, duplicate keys refused). A file is parsed once per content (path, size, modification time): a
    controller asks for its circuit when its parameters are checked, when it is built and when it is wired."""
    path = circuit_path(name_or_path)
    try:
        stat = path.stat()
    except (OSError, ValueError):  # no such file, a name too long, a NUL byte
        stat = None
    if stat is None or not path.is_file():
        shipped = sorted(p.stem for p in CIRCUITS.glob("*.yaml"))
        problem = Problem("", f"no such circuit; shipped: {shipped}", nearest(str(name_or_path), shipped))
        raise ScenarioError(str(path), [problem])
    data = _parse(str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    if not isinstance(data, dict):
        raise ScenarioError(str(path), [Problem("", f"expected a mapping; got {type(data).__name__}")])
    return copy.deepcopy(data)


@functools.lru_cache(maxsize=32)
def _parse(path: str, size: int, mtime_ns: int) -> Any:
    """The parsed file (cached per content; callers deep-copy it)."""
    del size, mtime_ns  # the cache key only
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ScenarioError(path, [Problem("", f"cannot read: {exc.strerror or exc}")]) from None
    return parse_yaml(data, path)


def load_circuit(name_or_path: str | Path, overrides: dict[str, Any] | None = None) -> Circuit:
    """Read, override (``{"couplings.0.weight": 1.5}``) and validate a circuit."""
    path = circuit_path(name_or_path)
    data = read_circuit_data(path)
    return apply_overrides(data, overrides or {}, file=str(path))


def apply_overrides(circuit_dict: dict, overrides: dict[str, Any], file: str = "<circuit>") -> Circuit:
    """Set values at dotted key paths (list items by index: ``joints.0.rg.sigma_s``), then re-validate.

    A mapping given as a value is merged, key by key, into the mapping or list already at its path, so the nested
    form that ``sfl ... --set modules.controller.params.circuit_overrides.joints.0.rg.sigma_s=1`` builds,
    ``{"joints": {"0": {"rg": {"sigma_s": 1}}}}``, is the same override as ``{"joints.0.rg.sigma_s": 1}``. Any other
    value replaces what is at its path. The input dict is not changed. A path that does not exist in the file is an
    error naming it (a new key inside an existing mapping is allowed: the schema then says whether it is valid)."""
    data = copy.deepcopy(circuit_dict)
    problems: list[Problem] = []
    for key, value in overrides.items():
        _override(data, str(key).split("."), value, (), problems)
    if problems:
        raise ScenarioError(file, problems)
    return validate_circuit(data, file)


def _override(node: Any, parts: list[str], value: Any, done: tuple, problems: list[Problem]) -> None:
    """Set ``value`` at ``parts`` below ``node`` (``done``: the key path of ``node``), merging mappings."""
    for depth, part in enumerate(parts[:-1]):
        node, problem = _child(node, part, ".".join((*done, *parts[: depth + 1])))
        if problem:
            problems.append(problem)
            return
    last, path = parts[-1], ".".join((*done, *parts))
    if isinstance(node, list):
        if not (last.isdigit() and int(last) < len(node)):
            problems.append(Problem(path, f"expected an index below {len(node)}; got {last!r}"))
            return
        index: Any = int(last)
    elif isinstance(node, dict):
        index = last
    else:
        problems.append(Problem(path, f"expected a mapping or list to set a key in; got {node!r}"))
        return
    present = node[index] if isinstance(node, list) or index in node else None
    if isinstance(value, dict) and isinstance(present, dict | list):
        for key, item in value.items():
            _override(present, str(key).split("."), item, (*done, *parts), problems)
    else:
        node[index] = value


def _child(node: Any, part: str, path: str) -> tuple[Any, Problem | None]:
    if isinstance(node, list):
        if part.isdigit() and int(part) < len(node):
            return node[int(part)], None
        return None, Problem(path, f"expected an index below {len(node)}; got {part!r}")
    if isinstance(node, dict):
        if part in node:
            return node[part], None
        keys = [str(k) for k in node]
        return None, Problem(path, f"no such key; expected one of {sorted(keys)}", nearest(part, keys))
    return None, Problem(path, f"expected a mapping or list; got {node!r}")
