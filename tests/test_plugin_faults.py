"""Plugin-fault corpus through the CLI (plugin contract v2, issue 11).

Every case drops one faulty plugin file into a ``--plugins-dir`` folder and
runs ``sitframe run`` on a tiny config (2 learning trials of 30 iterations,
``c = 4``, one collection room; most cases reuse the situations of one
module-scoped log through ``clusters_from`` so they skip collect and cluster).
Each asserts what a plugin author relies on:

* exactly one line on stderr, starting ``sitframe: error:``, naming the
  plugin's file and the component (or hook) and method; no ``Traceback``;
* exit status 2 when the fault is found while the run is being set up
  (import, registration, creation, the protocol check, ``bind``, the sensor's
  first reading) -- and then nothing is written -- or 3 when it happens while
  the run runs;
* for a fault during the run, the log exists with status ``failed`` and the
  same line in ``Log.failure``; when the fault is in learning trial ``k``, the
  trials before ``k`` are in the log and readable, and no later one is.

Most run-time faults fire in trial 1 (the component remembers
``trial.index`` from ``trial_start``), so the case also proves that the
finished trial 0 is kept. Cases marked ``xfail`` (strict) are known defects
outside the scheduler's ``simulate``/``Resolved``; the reason says what is wrong.
"""

from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from sitframe.cli.app import main
from sitframe.logs.reader import open_log

#: Imports and helpers every faulty plugin file starts with.
PRELUDE = '''
import math
import numpy as np
from sitframe import hookimpl, Proposal
from sitframe.plugins.arbiters import SingleArbiter
from sitframe.plugins.fcm_interpreter import FCMInterpreter
from sitframe.plugins.fuzzy_q import FuzzyQBehaviour
from sitframe.plugins.rewards import ObstacleAvoidanceReward
from sitframe.plugins.sonar import SonarRing


class InTrial1:
    """Remembers the trial it is in: a case's fault fires in learning trial 1 only."""
    k = -1

    def trial_start(self, trial):
        self.k = trial.index

    @property
    def now(self):
        return self.k == 1
'''

#: The run every case starts from (the case edits it).
CONFIG = textwrap.dedent("""
    [experiment]
    name = "fault"
    trials = 2
    iterations = 30
    seed = 3
    stages = ["collect", "cluster", "learn"]
    clusters_from = "{BASE}"

    [collect]
    worlds = ["collect-1"]

    [interpreter]
    component = "fcm"
    c = 4
    trials = 2

    [behaviours.avoid]
    component = "fuzzy-q"
    reward = "obstacle-avoidance"
    p = 5
""")

FRESH = 'clusters_from = "{BASE}"\n'  # removed by cases that collect and cluster themselves


@dataclass(frozen=True)
class Fault:
    """One faulty plugin and what the CLI must make of it.

    ``trial``: the learning trial the fault fires in (the log keeps the ones
    before it); ``None`` with ``code == 3`` means the fault is in the collect or
    cluster stage (the log exists, with no trials).
    """

    id: str
    plugin: str
    code: int
    must: tuple[str, ...]
    cfg: tuple[tuple[str, str], ...] = ()
    add: str = ""
    trial: int | None = None
    fresh: bool = False
    files: dict[str, str] = field(default_factory=dict)
    argv: tuple[str, ...] = ()
    xfail: str = ""
    kept: int | None = None  # trials the log keeps, if not the ``trial`` before the fault


def fault(id: str, plugin: str, code: int, *must: str, cfg: dict[str, str] | None = None,
          add: str = "", trial: int | None = None, fresh: bool = False,
          files: dict[str, str] | None = None, argv: tuple[str, ...] = (),
          xfail: str = "", kept: int | None = None) -> Fault:
    return Fault(id, textwrap.dedent(plugin), code, must, tuple((cfg or {}).items()), add,
                 trial, fresh, dict(files or {}), argv, xfail, kept)


REWARD = {'reward = "obstacle-avoidance"': 'reward = "bad"'}
BEHAVIOUR = {'component = "fuzzy-q"': 'component = "bad"'}
BEHAVIOUR_PLAIN = {**BEHAVIOUR, "p = 5\n": ""}  # a behaviour without fuzzy-q's parameters
INTERP = {'component = "fcm"': 'component = "bad"'}
EVOLVING_BEHAVIOUR = {**BEHAVIOUR, 'component = "fcm"': 'component = "evolving"'}
SENSOR_ADD = '\n[sensor]\ncomponent = "bad"\n'
ARBITER_ADD = '\n[arbiter]\ncomponent = "bad"\n'


def reward(body: str) -> str:
    """A reward plugin ``bad`` whose ``__call__`` is ``body`` (``self.now``: trial 1)."""
    return f'''
class Bad(InTrial1, ObstacleAvoidanceReward):
    name = "bad"

    def __call__(self, tr):
{textwrap.indent(textwrap.dedent(body).strip(), " " * 8)}

@hookimpl
def sitframe_rewards():
    return [Bad]
'''


def sensor(body: str) -> str:
    """A sonar plugin ``bad`` whose ``read`` is ``body`` (``r`` is the good reading)."""
    return f'''
class Bad(InTrial1, SonarRing):
    name = "bad"

    def read(self, world, pose, rng):
        r = super().read(world, pose, rng)
{textwrap.indent(textwrap.dedent(body).strip(), " " * 8)}

@hookimpl
def sitframe_sensors():
    return [Bad]
'''


def interpreter(body: str) -> str:
    """An FCM plugin ``bad`` whose ``memberships`` is ``body`` (``u`` is the good one)."""
    return f'''
class Bad(InTrial1, FCMInterpreter):
    name = "bad"

    def memberships(self, reading):
        u = super().memberships(reading)
{textwrap.indent(textwrap.dedent(body).strip(), " " * 8)}

@hookimpl
def sitframe_interpreters():
    return [Bad]
'''


def behaviour(body: str, method: str = "propose", args: str = "context") -> str:
    """A fuzzy-q plugin ``bad`` whose ``method`` is ``body`` (``good()`` calls the original)."""
    return f'''
class Bad(InTrial1, FuzzyQBehaviour):
    name = "bad"

    def {method}(self, {args}):
        good = lambda: super(Bad, self).{method}({args})
{textwrap.indent(textwrap.dedent(body).strip(), " " * 8)}

@hookimpl
def sitframe_behaviours():
    return [Bad]
'''


def arbiter(body: str) -> str:
    """A single-arbiter plugin ``bad`` whose ``combine`` is ``body``."""
    return f'''
class Bad(InTrial1, SingleArbiter):
    name = "bad"

    def combine(self, context, proposals):
        good = super().combine(context, proposals)
{textwrap.indent(textwrap.dedent(body).strip(), " " * 8)}

@hookimpl
def sitframe_arbiters():
    return [Bad]
'''


DUP = '''
from sitframe.plugins.rewards import ObstacleAvoidanceReward

class Dup(ObstacleAvoidanceReward):
    name = "dup"

@hookimpl
def sitframe_rewards():
    return [Dup]
'''

R = "reward 'bad' [behaviours.avoid.reward]"
S = "sensor 'bad' [sensor]"
In = "interpreter 'bad' [interpreter]"
B = "behaviour 'bad' [behaviours.avoid]"
FQ = "behaviour 'fuzzy-q' [behaviours.avoid]"
A = "arbiter 'bad' [arbiter]"

CASES: list[Fault] = [
    # -- rewards: __call__ must return a finite real number
    fault("reward-returns-str", reward('return "10" if self.now else 1.0'), 3,
          R, "__call__() in trial 1, iteration 0", "returned str '10'", cfg=REWARD, trial=1),
    fault("reward-returns-nan", reward("return math.nan if self.now else 1.0"), 3,
          R, "__call__() in trial 1", "returned nan, expected a finite reward", cfg=REWARD,
          trial=1),
    fault("reward-returns-none", reward("return None if self.now else 1.0"), 3,
          R, "__call__() in trial 1", "returned NoneType", cfg=REWARD, trial=1),
    fault("reward-returns-bool", reward("return True"), 3,
          R, "__call__() in trial 0", "returned bool", cfg=REWARD, trial=0),
    fault("reward-raises", reward("return 1 / 0 if self.now else 1.0"), 3,
          R, "__call__() in trial 1", "ZeroDivisionError: division by zero", cfg=REWARD,
          trial=1),
    fault("reward-calls-sys-exit", reward("""
              if self.now:
                  import sys
                  sys.exit("giving up")  # ended sitframe with status 1, no log status, no line
              return 1.0"""), 3, R, "__call__() in trial 1", "SystemExit: giving up", cfg=REWARD,
          trial=1),
    fault("reward-bind-raises", reward("return 1.0") + '''
def _bind(self, run):
    raise RuntimeError("no robot for me")
Bad.bind = _bind
''', 2, R, "bind()", "RuntimeError: no robot for me", cfg=REWARD),
    fault("reward-trial-start-raises", reward("return 1.0") + '''
def _start(self, trial):
    if trial.index == 1:
        raise KeyError("state")
Bad.trial_start = _start
''', 3, R, "trial_start() in trial 1", "KeyError: 'state'", cfg=REWARD, trial=1),
    fault("reward-trial-end-returns-list", reward("return 1.0") + '''
Bad.trial_end = lambda self, trial: [1, 2] if trial.index == 1 else {"ok": 1}
''', 3, R, "trial_end() in trial 1", "returned list, expected a dict", cfg=REWARD, trial=1),
    fault("reward-missing-call", '''
class Bad:
    name = "bad"
    __call__ = None

@hookimpl
def sitframe_rewards():
    return [Bad]
''', 2, R, "has no method '__call__'", cfg=REWARD),
    # -- sensors: read returns a finite (d,) float array
    fault("sensor-one-value-short-at-creation", sensor("return r[:-1]"), 2,
          S, "read()", "returned shape (7,), expected (8,)", add=SENSOR_ADD, fresh=True),
    fault("sensor-one-value-short-in-trial-1", sensor("return r[:-1] if self.now else r"), 3,
          S, "read() in trial 1, iteration 0", "returned shape (7,), expected (8,)",
          add=SENSOR_ADD, fresh=True, trial=1),
    fault("sensor-nan-in-trial-1", sensor("""
              if self.now:
                  r = r.copy()
                  r[2] = math.nan
              return r"""), 3,
          S, "read() in trial 1", "non-finite value (nan) in beam 2", add=SENSOR_ADD,
          fresh=True, trial=1),
    fault("sensor-negative-range-in-trial-1", sensor("return r - 5.0 if self.now else r"), 3,
          S, "read() in trial 1, iteration 0", "in beam 0, expected a range in [0, max_range = 3]",
          add=SENSOR_ADD, fresh=True, trial=1),  # was blamed on whatever used the reading
    fault("sensor-beyond-max-range-in-trial-1", sensor("return r * 10 if self.now else r"), 3,
          S, "read() in trial 1, iteration ", "expected a range in [0, max_range = 3]",
          add=SENSOR_ADD, fresh=True, trial=1),  # was accepted
    fault("sensor-returns-list", sensor("return r.tolist()"), 2,
          S, "read()", "returned list, expected a numpy array of shape (8,)",
          add=SENSOR_ADD, fresh=True),
    fault("sensor-turns-the-robot", sensor("""
              if self.now:
                  pose[2] += 0.1  # turned the robot unseen
              return r"""), 3,
          S, "read() in trial 1, iteration 0", "read-only", add=SENSOR_ADD, fresh=True, trial=1),
    fault("sensor-raises-in-trial-1", sensor("""
              if self.now:
                  raise IndexError("beam 9")
              return r"""), 3,
          S, "read() in trial 1, iteration 0", "IndexError: beam 9", add=SENSOR_ADD, fresh=True,
          trial=1),
    fault("sensor-raises-in-collect", '''
n = [0]

class Bad(SonarRing):
    name = "bad"

    def read(self, world, pose, rng):
        n[0] += 1
        if n[0] > 5:  # after the check at creation, during collect
            raise OSError("sonar unplugged")
        return super().read(world, pose, rng)

@hookimpl
def sitframe_sensors():
    return [Bad]
''', 3, S, "read()", "OSError: sonar unplugged", add=SENSOR_ADD, fresh=True),
    fault("sensor-missing-read", '''
class Bad:
    name = "bad"
    angles_deg = np.zeros(8)
    max_range = 3.0

@hookimpl
def sitframe_sensors():
    return [Bad]
''', 2, S, "has no method 'read'", add=SENSOR_ADD, fresh=True),
    fault("sensor-missing-angles", '''
class Bad:
    name = "bad"
    max_range = 3.0

    def read(self, world, pose, rng):
        return np.zeros(8)

@hookimpl
def sitframe_sensors():
    return [Bad]
''', 2, S, "has no attribute 'angles_deg'", add=SENSOR_ADD, fresh=True),
    fault("sensor-angles-nan", '''
class Bad(SonarRing):
    name = "bad"

    def __init__(self, **kw):
        super().__init__(**kw)
        self.angles_deg = self.angles_deg.copy()
        self.angles_deg[3] = math.nan  # was a traceback once the run was over

@hookimpl
def sitframe_sensors():
    return [Bad]
''', 2, S, "angles_deg()", "angles_deg holds nan, expected a non-empty 1-D array",
          add=SENSOR_ADD, fresh=True),
    fault("sensor-max-range-negative", '''
class Bad(SonarRing):
    name = "bad"

    def __init__(self, **kw):
        super().__init__(**kw)
        self.max_range = -3.0  # was blamed on whatever used the readings

@hookimpl
def sitframe_sensors():
    return [Bad]
''', 2, S, "max_range()", "max_range is -3.0, expected a finite number > 0",
          add=SENSOR_ADD, fresh=True),
    fault("sensor-property-raises", '''
class Bad(SonarRing):
    name = "bad"

    @property
    def max_range(self):
        raise RuntimeError("not calibrated")

    @max_range.setter
    def max_range(self, value):
        pass

@hookimpl
def sitframe_sensors():
    return [Bad]
''', 2, S, "max_range()", "RuntimeError: not calibrated", add=SENSOR_ADD, fresh=True),
    # -- interpreters: memberships are c non-negative numbers summing to 1
    fault("interpreter-memberships-wrong-length",
          interpreter("return np.append(u, 0.0) if self.now else u"), 3,
          In, "memberships() in trial 1", "returned shape (5,), expected (4,)", cfg=INTERP,
          trial=1),
    fault("interpreter-memberships-negative", interpreter("""
              if self.now:
                  return np.array([1.5, -0.5, 0.0, 0.0])
              return u"""), 3,
          In, "memberships() in trial 1", "negative membership (-0.5)", cfg=INTERP, trial=1),
    fault("interpreter-memberships-sum-not-1", interpreter("return u * 0.5 if self.now else u"),
          3, In, "memberships() in trial 1", "summing to 0.5, expected 1", cfg=INTERP, trial=1),
    fault("interpreter-memberships-raise", interpreter("""
              if self.now:
                  raise FloatingPointError("overflow")
              return u"""), 3,
          In, "memberships() in trial 1", "FloatingPointError: overflow", cfg=INTERP, trial=1),
    fault("evolving-interpreter-event-names-no-situation", '''
from sitframe.plugins.evolving import EvolvingInterpreter
from sitframe.situations.events import SituationEvent

class Bad(EvolvingInterpreter):  # was blamed on fuzzy-q's situations_changed (an IndexError)
    name = "bad"

    def events(self):
        return [SituationEvent("prune", 99, removed=(99,))]

@hookimpl
def sitframe_interpreters():
    return [Bad]
''', 3, In, "events() in trial 0", "'prune' event naming situation 99, expected ids 0 .. 47",
          cfg=INTERP, trial=0),
    fault("evolving-behaviour-situation-errors-negative",
          behaviour("e = good()\nreturn e - 1.0 if self.now else e", "situation_errors", ""),
          3, B, "situation_errors() in trial 1", "returned a TD error of -1.0 for situation 0, "
          "expected None or a (48,) array of finite absolute TD errors >= 0",
          cfg=EVOLVING_BEHAVIOUR, trial=1),
    fault("evolving-behaviour-situation-errors-list",
          behaviour("e = good()\nreturn e.tolist() if self.now else e", "situation_errors", ""),
          3, B, "situation_errors() in trial 1", "returned list", cfg=EVOLVING_BEHAVIOUR,
          trial=1),
    fault("evolving-behaviour-learning-converged-not-a-bool",
          behaviour("return 1 if self.now else good()", "learning_converged", ""),
          3, B, "learning_converged() in trial 1", "returned int 1, expected True or False",
          cfg=EVOLVING_BEHAVIOUR, trial=1),
    fault("evolving-behaviour-situations-changed-raises",
          behaviour("if self.now:\n    raise RuntimeError('no row for ' + str(event.id))\ngood()",
                    "situations_changed", "event"),
          3, B, "situations_changed() in trial 1", "RuntimeError: no row for",
          cfg={**EVOLVING_BEHAVIOUR, "c = 4\n": "c = 4\ncreate_distance = 0.01\n"}, trial=1),
    fault("evolving-interpreter-observe-errors-raises", '''
from sitframe.plugins.evolving import EvolvingInterpreter

class Bad(InTrial1, EvolvingInterpreter):
    name = "bad"

    def observe_errors(self, errors):
        if self.now:
            raise ValueError("errors of shape " + str(errors.shape))
        super().observe_errors(errors)

@hookimpl
def sitframe_interpreters():
    return [Bad]
''', 3, In, "observe_errors() in trial 1", "ValueError: errors of shape (48,)", cfg=INTERP,
          trial=1),
    fault("evolving-interpreter-without-events", '''
class Bad(FCMInterpreter):  # was a TypeError in the first learning trial
    name = "bad"
    evolving = True

@hookimpl
def sitframe_interpreters():
    return [Bad]
''', 2, In, "has no method 'events' (needed: it is evolving", cfg=INTERP),
    fault("interpreter-fit-raises", '''
class Bad(FCMInterpreter):
    name = "bad"

    def fit(self, X, rng):
        raise np.linalg.LinAlgError("singular")

@hookimpl
def sitframe_interpreters():
    return [Bad]
''', 3, In, "fit()", "LinAlgError: singular", cfg=INTERP, fresh=True),
    fault("interpreter-fit-returns-a-list", '''
class Bad(FCMInterpreter):
    name = "bad"

    def fit(self, X, rng):
        super().fit(X, rng)
        return ["centres"]

@hookimpl
def sitframe_interpreters():
    return [Bad]
''', 3, In, "fit()", "returned list, expected a dict", cfg=INTERP, fresh=True),
    fault("interpreter-n-situations-zero", '''
class Bad(FCMInterpreter):
    name = "bad"
    n_situations = 0

@hookimpl
def sitframe_interpreters():
    return [Bad]
''', 2, In, "n_situations()", "expected a positive integer", cfg=INTERP),
    fault("interpreter-n-situations-never-known", '''
class Bad(FCMInterpreter):  # was "int() argument must be ... not 'NoneType'"
    name = "bad"
    n_situations = None

@hookimpl
def sitframe_interpreters():
    return [Bad]
''', 3, In, "n_situations() in trial 0", "n_situations is None, expected a positive integer "
          "once the situations are fitted or loaded", cfg=INTERP, trial=0),
    # -- behaviours: propose returns a sitframe.Proposal with a finite heading
    fault("behaviour-propose-returns-none", behaviour("return None if self.now else good()"), 3,
          B, "propose() in trial 1, iteration 0", "returned NoneType None", cfg=BEHAVIOUR,
          trial=1),
    fault("behaviour-propose-returns-tuple",
          behaviour("return (10.0, 0.1) if self.now else good()"), 3,
          B, "propose() in trial 1", "returned tuple (10.0, 0.1), expected a sitframe.Proposal",
          cfg=BEHAVIOUR, trial=1),
    fault("behaviour-propose-nan-heading",
          behaviour("return Proposal(math.nan) if self.now else good()"), 3,
          B, "propose() in trial 1", "heading_deg nan", cfg=BEHAVIOUR, trial=1),
    fault("behaviour-propose-activation-above-1",
          behaviour("return Proposal(0.0, activation=1.5) if self.now else good()"), 3,
          B, "propose() in trial 1", "activation 1.5, expected None or a number in [0, 1]",
          cfg=BEHAVIOUR, trial=1),
    fault("behaviour-propose-negative-speed",
          behaviour("return Proposal(0.0, -0.1) if self.now else good()"), 3,
          B, "propose() in trial 1", "speed_m_s -0.1, expected None or a finite number >= 0",
          cfg=BEHAVIOUR, trial=1),
    fault("behaviour-propose-raises", behaviour("""
              if self.now:
                  raise ValueError("no rule fires")
              return good()"""), 3,
          B, "propose() in trial 1", "ValueError: no rule fires", cfg=BEHAVIOUR, trial=1),
    fault("behaviour-normalises-memberships-in-place", behaviour("""
              if self.now:
                  context.memberships[:] = 0.0  # was blamed on the interpreter
              return good()"""), 3,
          B, "propose() in trial 1, iteration 0", "read-only", "copy one to change it",
          cfg=BEHAVIOUR, trial=1),
    fault("behaviour-learn-raises", behaviour("""
              if self.now:
                  raise RuntimeError("diverged")
              good()""", "learn", "transition, reward"), 3,
          B, "learn() in trial 1", "RuntimeError: diverged", cfg=BEHAVIOUR, trial=1),
    fault("behaviour-policy-returns-dict",
          behaviour('return {"heading": 1} if self.k == 1 else good()', "policy", ""), 3,
          B, "policy() in trial 1", "returned dict, expected a sitframe.LearnedPolicy",
          cfg=BEHAVIOUR, trial=1),
    fault("reward-huge-overflows-q", reward("return 1.7e308 if self.now else 1.0"), 3,
          FQ, "policy() in trial 1", "'heading' q hold", "expected finite values", cfg=REWARD,
          trial=1),  # the log kept an infinite Q table
    fault("behaviour-trial-data-empty-key",
          behaviour('return {"": 1} if self.k == 1 else good()', "trial_data", ""), 3,
          B, "trial_data() in trial 1", "expected a dict of non-empty string keys",
          cfg=BEHAVIOUR, trial=1),
    fault("behaviour-convergence-iteration-not-an-integer",  # was a traceback (summary)
          behaviour('return {**good(), "convergence_iteration": "late"} if self.k == 1 else good()',
                    "trial_data", ""), 3,
          B, "trial_data() in trial 1", "convergence_iteration = 'late', expected an integer in "
          "[-1, 30]", cfg=BEHAVIOUR, trial=1),
    fault("behaviour-missing-propose", '''
class Bad:
    name = "bad"

    def reset(self, rng, n_situations, iterations):
        pass

@hookimpl
def sitframe_behaviours():
    return [Bad]
''', 2, B, "has no method 'propose'", cfg=BEHAVIOUR_PLAIN),
    fault("behaviour-reset-without-iterations", '''
class Bad(FuzzyQBehaviour):  # was a TypeError in trial 0 (exit 3, a failed log)
    name = "bad"

    def reset(self, rng, n_situations):
        super().reset(rng, n_situations, 100)

@hookimpl
def sitframe_behaviours():
    return [Bad]
''', 2, B, "reset(rng, n_situations) cannot be called as reset(rng, n_situations, iterations)",
          cfg=BEHAVIOUR),
    fault("behaviour-with-reward-but-no-learn", '''
class Bad:
    name = "bad"

    def reset(self, rng, n_situations, iterations):
        pass

    def propose(self, context):
        return Proposal(0.0)

@hookimpl
def sitframe_behaviours():
    return [Bad]
''', 2, B, "has no method 'learn'", cfg=BEHAVIOUR_PLAIN),
    fault("behaviour-learns-without-policy", '''
class Bad(FuzzyQBehaviour):  # its evaluations used to run a fresh, unlearned instance
    name = "bad"
    policy = None

@hookimpl
def sitframe_behaviours():
    return [Bad]
''', 2, B, "has no method 'policy' (needed: it learns from a reward and the run has an "
          "evaluate stage", cfg={**BEHAVIOUR, '"learn"]': '"learn", "evaluate"]'},
          add='\n[evaluate]\nworlds = ["novel-1"]\n'),
    fault("behaviour-policy-without-load-policy", '''
class Bad(FuzzyQBehaviour):  # was a traceback (AttributeError) at the first evaluation
    name = "bad"
    load_policy = None

@hookimpl
def sitframe_behaviours():
    return [Bad]
''', 2, B, "has no method 'load_policy' (needed: it has policy() or policy_from", cfg=BEHAVIOUR),
    # -- arbiters: combine returns (Proposal, (k,) weights); rules checked at bind
    fault("arbiter-raises", arbiter("""
              if self.now:
                  raise ZeroDivisionError("no weight")
              return good"""), 3,
          A, "combine() in trial 1", "ZeroDivisionError: no weight", add=ARBITER_ADD, trial=1),
    fault("arbiter-wrong-weights",
          arbiter("return (good[0], np.ones(3)) if self.now else good"), 3,
          A, "combine() in trial 1", "weights of shape (3,), expected (1,)", add=ARBITER_ADD,
          trial=1),
    fault("arbiter-negative-weights",  # was logged as a behaviour's weight, unnoticed
          arbiter("return (good[0], -good[1]) if self.now else good"), 3,
          A, "combine() in trial 1", "returned negative weights [-1.0], expected the share each "
          "proposal got (>= 0)", add=ARBITER_ADD, trial=1),
    fault("arbiter-empties-the-proposals",  # was a traceback when the trial was logged
          arbiter("proposals.clear()\nreturn good"), 3,
          A, "combine() in trial 0, iteration 0", "changed the proposals it was given: 0 left of 1",
          add=ARBITER_ADD, trial=0),
    fault("arbiter-returns-a-proposal-only",
          arbiter("return good[0] if self.now else good"), 3,
          A, "combine() in trial 1", "returned Proposal, expected a tuple (Proposal, weights",
          add=ARBITER_ADD, trial=1),
    fault("arbiter-rules-name-unknown-label", "", 2,
          "fault.toml: arbiter.rules[0].behaviour:", "names behaviour 'avod'",
          add='\n[arbiter]\ncomponent = "priority"\nrules = [{behaviour = "avod"}]\n'),
    # -- observers
    fault("observer-step-raises", '''
@hookimpl
def sitframe_step(record):
    if record.trial == 1 and record.transition.before.iteration == 7:
        raise RuntimeError("display lost")
''', 3, "p.py", "sitframe_step() in trial 1, iteration 7", "RuntimeError: display lost",
          trial=1),
    fault("observer-trial-data-not-a-dict", '''
@hookimpl
def sitframe_trial_data(trial):
    return {"n": 1} if trial.index == 0 else [1, 2]
''', 3, "p.py", "sitframe_trial_data() in trial 1", "returned list, expected a dict",
          trial=1),
    fault("observer-trial-data-holds-objects", '''
@hookimpl
def sitframe_trial_data(trial):  # was blamed on the HDF5 logger, which could not write it
    return {"n": 1} if trial.index == 0 else {"names": np.array(["a", "b"])}
''', 3, "p.py", "sitframe_trial_data() in trial 1", "key 'names': ndarray of dtype <U1",
          trial=1),
    fault("interpreter-state-ragged", '''
class Bad(FCMInterpreter):
    name = "bad"

    def state(self):
        return {**super().state(), "history": [[1.0], [1.0, 2.0]]}

@hookimpl
def sitframe_interpreters():
    return [Bad]
''', 3, In, "state()", "key 'history': list that is no rectangular array", cfg=INTERP,
          fresh=True),
    fault("observer-trial-data-raises", '''
@hookimpl
def sitframe_trial_data(trial):
    return {"n": 1 / trial.index}
''', 3, "p.py", "sitframe_trial_data() in trial 0", "ZeroDivisionError", trial=0),
    # -- registration and loading
    fault("hook-returns-a-class-not-a-list", '''
class Bad(ObstacleAvoidanceReward):
    name = "bad"

@hookimpl
def sitframe_rewards():
    return Bad
''', 2, "p.py", "hook sitframe_rewards must return a list", "got type", cfg=REWARD),
    fault("hook-returns-an-instance", '''
class Bad(ObstacleAvoidanceReward):
    name = "bad"

@hookimpl
def sitframe_rewards():
    return [Bad()]
''', 2, "fault.toml: behaviours.avoid.reward:", "__call__() missing 1 required positional",
          "the hook must return the class, not an instance (Bad() was registered)", cfg=REWARD),
    fault("factory-positional-only", '''
class Bad(ObstacleAvoidanceReward):
    name = "bad"

    def __init__(self, collision, /):  # was "unknown parameter ...; accepted: " (nothing)
        super().__init__(collision=collision)

@hookimpl
def sitframe_rewards():
    return [Bad]
''', 2, "fault.toml: behaviours.avoid.reward_params.collision:", "'collision' is a positional-only "
          "parameter of 'bad'", cfg={**REWARD, "p = 5": "p = 5\nreward_params = {collision = 1}"}),
    fault("hook-name-misspelt", '''
@hookimpl
def sitframe_reward():
    return []
''', 2, "p.py", "sitframe_reward", "the hooks are listed in sitframe.contract.hookspecs"),
    fault("hook-without-hookimpl", '''
class Bad(ObstacleAvoidanceReward):
    name = "bad"

def sitframe_rewards():  # was never called: "unknown reward 'bad'"
    return [Bad]
''', 2, "p.py", "sitframe_rewards is not decorated with @sitframe.hookimpl", cfg=REWARD),
    fault("hooks-on-a-class", '''
class Observer:  # its hooks were silently never called
    @hookimpl
    def sitframe_step(self, record):
        pass
''', 2, "p.py", "class Observer implements sitframe_step, but a plugin module's hooks are its "
          "functions"),
    fault("hook-calls-sys-exit", '''
import sys

@hookimpl
def sitframe_rewards():
    sys.exit(1)
''', 2, "p.py", "raised in hook sitframe_rewards: SystemExit: 1"),
    fault("hook-raises", '''
@hookimpl
def sitframe_behaviours():
    raise ImportError("optional dependency missing")
''', 2, "p.py", "raised in hook sitframe_behaviours", "ImportError: optional dependency"),
    fault("duplicate-component-names", DUP, 2,
          "reward name 'dup' is registered by two plugins", "p.py", "q.py",
          files={"pl/q.py": DUP}),
    fault("plugin-syntax-error", "def oops(:\n", 2, "p.py:", "syntax error"),
    fault("plugin-import-error", "import not_a_module_xyz\n", 2, "p.py:", "failed to import",
          "ModuleNotFoundError"),
    fault("factory-raises", '''
class Bad(ObstacleAvoidanceReward):
    name = "bad"

    def __init__(self):
        raise RuntimeError("licence expired")

@hookimpl
def sitframe_rewards():
    return [Bad]
''', 2, "p.py", "creating reward 'bad' failed", "RuntimeError: licence expired", cfg=REWARD),
    fault("bind-raises-in-trial-1", '''
started = []

class Bad(SingleArbiter):
    name = "bad"

    def bind(self, run):  # each trial creates and binds its own arbiter
        if started:
            raise RuntimeError("bound again")

    def trial_start(self, trial):
        started.append(trial.index)

@hookimpl
def sitframe_arbiters():
    return [Bad]
''', 3, A, "bind() in trial 1", "RuntimeError: bound again", add=ARBITER_ADD, trial=1),
    # -- a fault in a worker process (trial 0: with two workers, trial 1 may not have started)
    fault("reward-raises-in-a-worker", reward("return 1 / 0 if self.k == 0 else 1.0"), 3,
          R, "__call__() in trial 0, iteration 0", "ZeroDivisionError", cfg=REWARD, trial=0,
          argv=("--workers", "2")),
    fault("worker-fault-keeps-the-earlier-trial", '''
import time

class Bad(InTrial1, ObstacleAvoidanceReward):
    name = "bad"

    def __call__(self, tr):
        if self.k == 0:
            time.sleep(0.05)  # trial 0 is still running when trial 1 fails
        if self.now:
            raise RuntimeError("late")
        return 1.0

@hookimpl
def sitframe_rewards():
    return [Bad]
''', 3, R, "__call__() in trial 1, iteration 0", "RuntimeError: late", cfg=REWARD, trial=1,
          argv=("--workers", "2")),
    # -- observers of the main process
    fault("observer-trial-end-raises", '''
@hookimpl
def sitframe_trial_end(run, trial):
    if trial.index == 1:
        raise RuntimeError("plot window closed")
''', 3, "p.py", "sitframe_trial_end() in trial 1", "RuntimeError: plot window closed",
          trial=1, kept=2),  # trial 1 had finished: the logger (called last) still wrote it
    fault("observer-stage-end-raises", '''
@hookimpl
def sitframe_stage_end(run, stage, data):
    if stage == "cluster":
        raise RuntimeError("no display for the centres")
''', 3, "p.py", "sitframe_stage_end()", "RuntimeError: no display", fresh=True),
    fault("observer-trial-end-overwrites-another-plugins-data", '''
@hookimpl
def sitframe_trial_end(run, trial):  # was silently logged in place of the other's
    if trial.index == 1:
        trial.plugin_data["hdf5-logger"] = {"x": 1}
''', 3, "p.py", "sitframe_trial_end() in trial 1", "changed trial.plugin_data['hdf5-logger'], "
          "which is not its own (its own is trial.plugin_data['p'])", trial=1, kept=2),
    fault("observer-run-start-raises", '''
@hookimpl
def sitframe_run_start(run):
    raise RuntimeError("no terminal")
''', 3, "p.py", "sitframe_run_start()", "RuntimeError: no terminal"),
    fault("observer-run-end-raises", '''
@hookimpl
def sitframe_run_end(run, status):
    raise RuntimeError("cannot save the plot")
''', 3, "p.py", "sitframe_run_end()", "RuntimeError: cannot save the plot", kept=2),
]


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A log with fitted situations (c = 4) that most cases reuse."""
    d = tmp_path_factory.mktemp("faults-base")
    cfg = d / "base.toml"
    cfg.write_text(CONFIG.replace(FRESH, ""))
    out = d / "base.h5"
    assert main(["run", str(cfg), "--out", str(out), "--json", "--trials", "1",
                 "--workers", "1"]) == 0
    return out


def _config(c: Fault, base: Path) -> str:
    text = CONFIG.replace("{BASE}", str(base))
    if c.fresh:
        text = text.replace(FRESH.replace("{BASE}", str(base)), "")
    for old, new in c.cfg:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text + c.add


@pytest.mark.parametrize("c", [
    pytest.param(c, id=c.id, marks=[pytest.mark.xfail(strict=True, reason=c.xfail)] if c.xfail
                 else []) for c in CASES])
def test_plugin_fault(c: Fault, base: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                      capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("SITFRAME_TRACEBACK", raising=False)
    (tmp_path / "pl").mkdir()
    if c.plugin:
        (tmp_path / "pl" / "p.py").write_text(
            c.plugin if c.id.startswith("plugin-") else PRELUDE + c.plugin)
    for name, text in c.files.items():
        (tmp_path / name).write_text(PRELUDE + text)
    (tmp_path / "fault.toml").write_text(_config(c, base))
    code = main(["--plugins-dir", "pl", "run", "fault.toml", "--out", "out.h5", "--json",
                 "--workers", "1", *c.argv])
    out, err = capsys.readouterr()
    assert code == c.code, err
    assert "Traceback" not in err + out
    assert re.fullmatch(r"sitframe: error: [^\n]+\n", err), f"not one line: {err!r}"
    for m in c.must:
        assert m in err, f"{m!r} not in {err!r}"
    log_path = tmp_path / "out.h5"
    if c.code == 2:
        assert not log_path.exists(), "a log was written for a fault found at set-up"
        return
    log = open_log(log_path)
    assert log.status == "failed"
    assert log.failure == err[len("sitframe: error: "):-1]
    done = list(range(c.kept if c.kept is not None else c.trial or 0))
    assert log.trial_indices() == done
    for k in done:
        trial = log.trial(k)
        assert trial.arrays["reading"].shape == (30, 8)


def test_corpus_size() -> None:
    assert len(CASES) >= 25
    assert len({c.id for c in CASES}) == len(CASES)
