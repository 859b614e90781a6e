"""Difficulty on request: adapt_to_success on a tiny house with an agent whose success depends on where one
object stands, and a G that pushes that object a fixed stride per edit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from adaptenv.adapt.edits import replay
from adaptenv.adapt.generators import GenerationResult, StepRecord
from adaptenv.adapt.target import Measurement, adapt_to_success, check_target, closer, focus_order
from adaptenv.adapt.validation import EditValidator
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.errors import ConfigError
from adaptenv.sim.spec import END

OBJECT = "DogBed|2|6"


@pytest.fixture(scope="module")
def tiny():
    hs = load_house_set("preset:tiny")
    return hs.houses[hs.names.index("tiny_0002")]


class ShyExpert(ExpertPolicy):
    """The expert, except that it gives up at once on episode k (k = seed % 1000) when k < the number of whole
    ``per`` metres ``OBJECT`` stands from ``home``: its success falls as the object moves away (with
    ``measured_only``, on the measured draw alone: seeds below 1000)."""

    name = "shy-expert"

    def __init__(self, home: tuple[float, float], per: float = 0.2, measured_only: bool = False):
        super().__init__()
        self.home, self.per, self.measured_only = home, per, measured_only
        self._quit = np.zeros(0, bool)

    def act(self, obs, state, done):
        actions, state = super().act(obs, state, done)
        ctx = self.bound()
        if len(self._quit) != len(done):
            self._quit = np.zeros(len(done), bool)
        for i in np.flatnonzero(done):
            world = ctx.worlds[int(ctx.env_idx[i])]
            x, z = next(t.center for t in world.instances if t.object_id == OBJECT)
            fails = math.floor(math.hypot(x - self.home[0], z - self.home[1]) / self.per + 1e-6)
            seed = int(ctx.seeds[i])
            self._quit[i] = seed % 1000 < fails and (seed < 1000 or not self.measured_only)
        actions = np.where(self._quit, END, actions)
        return actions, state


class Pusher:
    """A G that moves ``OBJECT`` ``stride`` grid units along x (the other way once blocked), one validated edit."""

    name = "pusher"

    def __init__(self, stride: float):
        self.stride, self.calls = stride, 0

    def generate(self, house, analysis, *, steps, context, rng):
        self.calls += 1
        ep = context.episode
        v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2], plausibility=False)
        result = GenerationResult(house=v.house, steps=[], edit_log=v.log, generator=self.name)
        for dx in (self.stride, -self.stride, 0.0):
            edit = v.try_edit(OBJECT, dx, self.stride if dx == 0.0 else 0.0, None, source=self.name, intent="push")
            if edit.accepted and edit.changed:
                result.steps.append(StepRecord(step=0, status="applied", edit=edit))
                break
        result.house = v.house
        return result


def home_of(house) -> tuple[float, float]:
    o = house.object_by_id(OBJECT)
    return o.position.x, o.position.z


def run(tiny, target, *, stride=3.0, tolerance=0.1, max_edits=8, patience=3, per=0.2, stop_gap=None):
    return adapt_to_success(tiny, ShyExpert(home_of(tiny), per), Pusher(stride), target, tolerance=tolerance,
                            episodes=10, max_edits=max_edits, patience=patience, seed=0, name="tiny", stop_gap=stop_gap)


def test_success_is_brought_within_tolerance_and_each_kept_edit_comes_closer(tiny):
    res = run(tiny, 0.7, tolerance=0.1)
    assert res.before.success == 1.0
    assert res.stopped == "within the stop gap 0.05" and res.reached and res.gap <= 0.05 + 1e-9
    assert 1 <= len(res.edits) <= 8 and res.success_trace[0] == 1.0 and res.success_trace[-1] == res.success
    gaps = [abs(s - 0.7) for s in res.success_trace]
    assert all(b <= a + 1e-9 for a, b in zip(gaps, gaps[1:], strict=False))
    # the returned house is the original with the kept edits replayed, and it measures what the result says
    again = replay(tiny, res.edits)
    assert home_of(again) == home_of(res.house) != home_of(tiny)
    assert res.to_dict()["edits"] == len(res.edits) and res.to_dict()["success"] == res.success
    assert "target success 0.70" in res.line() and f"reached {res.success:.2f}" in res.line()
    assert res.original is tiny and home_of(tiny) == home_of(res.original)  # the input is not modified


def test_the_edit_budget_stops_the_run_at_the_closest_house(tiny):
    res = run(tiny, 0.2, tolerance=0.0, max_edits=2, stride=3.0)
    assert res.stopped == "edit budget used" and len(res.edits) == 2 and not res.reached
    assert res.success < res.before.success and res.gap == pytest.approx(abs(res.success - 0.2))


def test_an_edit_that_overshoots_is_dropped(tiny):
    # big strides drop success by several episodes at a time: near P = 0.65 one overshoots and is refused
    res = run(tiny, 0.65, tolerance=0.0, stride=6.0, max_edits=6, patience=2)
    dropped = [r for r in res.rounds if not r.kept and r.success is not None]
    assert dropped, [r.reason for r in res.rounds]
    assert all(abs(r.success - 0.65) > res.gap for r in dropped)
    assert res.stopped.startswith("no kept edit in 2 rounds")


def test_already_within_tolerance_needs_no_edit(tiny):
    g = Pusher(3.0)
    res = adapt_to_success(tiny, ShyExpert(home_of(tiny)), g, 0.95, tolerance=0.1, episodes=10, name="tiny")
    assert res.stopped == "within the stop gap 0.05" and res.edits == [] and g.calls == 0 and res.house is tiny


class StridePusher(Pusher):
    """A Pusher whose stride cycles through ``strides``, one per call."""

    def __init__(self, strides: list[float]):
        super().__init__(strides[0])
        self.strides = strides

    def generate(self, house, analysis, *, steps, context, rng):
        self.stride = self.strides[self.calls % len(self.strides)]
        return super().generate(house, analysis, steps=steps, context=context, rng=rng)


def test_choices_measure_every_proposal_of_a_round_and_keep_the_closest(tiny):
    g = StridePusher([2.0, 12.0, 6.0])
    res = adapt_to_success(tiny, ShyExpert(home_of(tiny)), g, 0.5, tolerance=0.0, episodes=10, max_edits=1,
                           seed=0, name="tiny", choices=3)
    assert g.calls == 3 and res.round_count == 1 and len(res.rounds) == 3 and len(res.edits) == 1
    gaps = [abs(r.success - 0.5) for r in res.rounds]
    assert len(set(gaps)) > 1  # the three strides measure differently, so the choice matters
    kept = next(r for r in res.rounds if r.kept)
    assert abs(kept.success - 0.5) == min(gaps) == res.gap
    assert res.to_dict()["rounds"] == 1 and res.to_dict()["proposed"] == 3
    # with one choice the round's first proposal is kept as soon as it comes closer
    one = adapt_to_success(tiny, ShyExpert(home_of(tiny)), StridePusher([2.0, 12.0, 6.0]), 0.5, tolerance=0.0,
                           episodes=10, max_edits=1, seed=0, name="tiny")
    assert one.round_count == len(one.rounds) == 1 and one.rounds[0].success == res.rounds[0].success


@pytest.mark.parametrize("choices", [0, -1, 2.5])
def test_choices_other_than_a_whole_number_from_one_are_refused(tiny, choices):
    with pytest.raises(ConfigError, match="choices"):
        adapt_to_success(tiny, ShyExpert(home_of(tiny)), Pusher(3.0), 0.5, episodes=4, choices=choices)


def test_acceptance_rule_and_focus():
    m = lambda s, spl: Measurement(tuple([True] * int(s * 10) + [False] * (10 - int(s * 10))), (spl,) * 10, 0)  # noqa: E731
    assert closer(0.5, m(0.9, 0.8), m(0.7, 0.8))[0]
    assert not closer(0.5, m(0.6, 0.8), m(0.2, 0.5))[0]  # overshoot by more than it gained
    assert closer(0.5, m(0.9, 0.8), m(0.9, 0.7))[0] and not closer(0.5, m(0.9, 0.8), m(0.9, 0.85))[0]
    assert closer(0.5, m(0.2, 0.1), m(0.2, 0.2))[0]  # below P: higher SPL at equal success is easier
    mixed = Measurement((True, False, True), (0.9, 0.0, 0.4), 0)
    assert focus_order(0.5, mixed) == [2, 0] and focus_order(0.9, mixed) == [1]


@pytest.mark.parametrize("p", [0.0, 1.0, -0.2, 1.5, float("nan")])
def test_a_target_outside_zero_one_is_refused(p):
    with pytest.raises(ConfigError, match="strictly between 0 and 1"):
        check_target(p)
    with pytest.raises(ConfigError, match="tolerance"):
        check_target(0.5, 1.0)


# ----------------------------------------------------------------------------- the command line

def _tiny_file(tiny, tmp_path):
    from adaptenv.scene.house import save_house

    return str(save_house(tiny, tmp_path / "tiny.json"))


@pytest.mark.parametrize("args", [["--target-success", "1.5"], ["--target-success", "0"],
                                  ["--target-success", "0.5", "--target-tolerance", "2"],
                                  ["--target-success", "0.5", "--diagnose", "2"]])
def test_cli_refuses_a_bad_target_in_one_line_before_any_work(tiny, tmp_path, args):
    from typer.testing import CliRunner

    from adaptenv.cli import app

    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["adapt", _tiny_file(tiny, tmp_path), "-o", str(out), *args])
    assert isinstance(result.exception, ConfigError), result.output
    assert "--target-" in str(result.exception) and "\n" not in str(result.exception)
    assert not out.exists()


def test_cli_reports_target_reached_success_gap_and_edits(tiny, tmp_path):
    import json

    from typer.testing import CliRunner

    from adaptenv.cli import app

    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["adapt", _tiny_file(tiny, tmp_path), "--policy", "expert", "--target-success",
                                      "0.5", "--target-episodes", "4", "--steps", "1", "--target-choices", "2", "-o", str(out),
                                      "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)["target_success"]
    assert doc["target"] == 0.5 and doc["episodes"] == 4 and doc["edits"] <= 1
    assert doc["rounds"] <= doc["proposed"] <= 2 * doc["rounds"]  # two edits proposed per round
    assert doc["gap"] == pytest.approx(abs(doc["success"] - 0.5)) and len(doc["success_trace"]) == doc["edits"] + 1
    saved = json.loads((out / "summary.json").read_text())
    assert saved["target_success"]["success"] == doc["success"] and saved["edits_applied"] == doc["edits"]
    assert {"house.json", "before_after.png", "edits.json"} <= {p.name for p in out.iterdir()}
    text = CliRunner().invoke(app, ["adapt", _tiny_file(tiny, tmp_path), "--policy", "expert", "--target-success",
                                    "0.5", "--target-episodes", "4", "--steps", "1", "-o", str(out), "--force"])
    assert text.exit_code == 0, text.output
    assert f"target success 0.50 +/- 0.10: reached {doc['success']:.2f}" in text.output
    fresh_gap = abs(doc["fresh_success"] - 0.5)
    assert doc["fresh_gap"] == pytest.approx(fresh_gap) and doc["fresh_reached"] == (fresh_gap <= 0.10 + 1e-9)
    assert (f"on 3 fresh action draws per episode (not selected on): success {doc['fresh_success_before']:.2f} -> "
            f"{doc['fresh_success']:.2f}, gap {fresh_gap:.2f}: {'within' if fresh_gap <= 0.10 + 1e-9 else 'not within'} "
            "the tolerance") in text.output
    bad = CliRunner().invoke(app, ["adapt", _tiny_file(tiny, tmp_path), "--target-success", "0.5",
                                   "--target-choices", "0", "-o", str(tmp_path / "none")])
    assert bad.exit_code == 2 and "--target-choices" in bad.output and not (tmp_path / "none").exists()
    gap = CliRunner().invoke(app, ["adapt", _tiny_file(tiny, tmp_path), "--target-success", "0.5",
                                   "--target-stop-gap", "0.2", "-o", str(tmp_path / "none")])
    assert isinstance(gap.exception, ConfigError) and "--target-stop-gap 0.2" in str(gap.exception)
    assert not (tmp_path / "none").exists()
    drawn = CliRunner().invoke(app, ["adapt", _tiny_file(tiny, tmp_path), "--policy", "expert", "--target-success",
                                     "0.5", "--target-episodes", "4", "--target-draws", "2", "--steps", "1", "-o",
                                     str(tmp_path / "drawn"), "--json"])
    assert drawn.exit_code == 0, drawn.output
    assert json.loads(drawn.output)["target_success"]["draws"] == 2
    assert json.loads(drawn.output)["target_success"]["stop_gap"] == pytest.approx(0.05)


class SeedLog(ExpertPolicy):
    """The expert, noting the seed of every episode it starts."""

    name = "seed-log"

    def __init__(self):
        super().__init__()
        self.seeds: list[int] = []

    def act(self, obs, state, done):
        ctx = self.bound()
        self.seeds += [int(ctx.seeds[i]) for i in np.flatnonzero(done)]
        return super().act(obs, state, done)


def test_the_run_ends_with_a_check_on_fresh_action_draws(tiny):
    res = run(tiny, 0.7, tolerance=0.1)
    # the shy expert decides by seed % 1000, which a fresh draw keeps: the fresh check agrees with the run
    assert res.fresh_draws == 3 and len(res.fresh_after.successes) == 3 * len(res.episodes)
    assert res.fresh_before.success == res.before.success and res.fresh_after.success == res.success
    doc = res.to_dict()
    assert (doc["fresh_draws"], doc["fresh_success_before"], doc["fresh_success"]) == (3, 1.0, res.success)
    assert f"on fresh draws 1.00 -> {res.success:.2f}" in res.line()
    skipped = adapt_to_success(tiny, ShyExpert(home_of(tiny)), Pusher(3.0), 0.7, episodes=10, seed=0, name="tiny",
                               fresh_draws=0)
    assert skipped.fresh_after is None and skipped.to_dict()["fresh_success"] is None
    assert "fresh" not in skipped.line() and skipped.success == res.success


def test_fresh_draws_use_new_seeds_for_the_same_episodes(tiny):
    from adaptenv.adapt.target import fresh_measurement, measurement_episodes
    from adaptenv.sim.world import compile_world

    world = compile_world(tiny, "tiny")
    eps = measurement_episodes(world, 4, 0)
    policy = SeedLog()
    m = fresh_measurement(world, eps, policy, 2)
    assert len(m.successes) == 8 and len(set(policy.seeds)) == 8
    assert not set(policy.seeds) & {e.seed for e in eps}
    assert sorted(s % 1000 for s in policy.seeds) == sorted(2 * [e.seed % 1000 for e in eps])


@pytest.mark.parametrize("draws", [-1, 1.5])
def test_a_bad_number_of_fresh_draws_is_refused(tiny, draws):
    with pytest.raises(ConfigError, match="fresh_draws"):
        adapt_to_success(tiny, ExpertPolicy(), Pusher(3.0), 0.5, episodes=2, name="tiny", fresh_draws=draws)


def test_several_draws_per_episode_measure_each_episode_with_its_own_seeds(tiny):
    one = run(tiny, 0.7, tolerance=0.1)
    two = adapt_to_success(tiny, ShyExpert(home_of(tiny)), Pusher(3.0), 0.7, tolerance=0.1, episodes=10,
                           max_edits=8, patience=3, seed=0, name="tiny", draws=2)
    # the shy expert decides by seed % 1000, the same in every draw: the same run, with twice the rollouts
    assert two.draws == 2 and len(two.before.successes) == 20 and len(two.episodes) == 10
    assert two.success_trace == one.success_trace and two.to_dict()["draws"] == 2
    assert all(0 <= r.episode < 20 for r in two.rounds) and two.measure_steps > one.measure_steps


def test_confirmed_edits_must_come_closer_on_other_draws_too(tiny):
    from adaptenv.adapt.target import CONFIRM_SEED_STRIDE, FRESH_SEED_STRIDE

    plain = run(tiny, 0.7, tolerance=0.1)
    kw = dict(tolerance=0.1, episodes=10, max_edits=8, patience=3, seed=0, name="tiny")
    same = adapt_to_success(tiny, ShyExpert(home_of(tiny)), Pusher(3.0), 0.7, confirm=True, **kw)
    # where every draw agrees, confirming keeps the same edits, with more rollouts
    assert same.success_trace == plain.success_trace and same.measure_steps > plain.measure_steps
    assert same.to_dict()["confirm"] is True and plain.to_dict()["confirm"] is False
    assert all("and on the confirming draws" in r.reason for r in same.rounds if r.kept)
    # an edit whose gain shows on the measured draw alone is kept without confirming, dropped with it
    noisy = adapt_to_success(tiny, ShyExpert(home_of(tiny), measured_only=True), Pusher(3.0), 0.7, **kw)
    checked = adapt_to_success(tiny, ShyExpert(home_of(tiny), measured_only=True), Pusher(3.0), 0.7, confirm=True,
                               **kw)
    assert noisy.edits and noisy.success < 1.0
    assert not checked.edits and checked.success == 1.0
    assert any("not on the confirming draws" in r.reason for r in checked.rounds)
    assert CONFIRM_SEED_STRIDE != FRESH_SEED_STRIDE and CONFIRM_SEED_STRIDE % 1000 == 0


def test_refreshed_draws_measure_the_kept_house_anew(tiny):
    from adaptenv.adapt.target import (
        CONFIRM_SEED_STRIDE,
        DRAW_SEED_STRIDE,
        FRESH_SEED_STRIDE,
        REFRESH_SEED_STRIDE,
    )

    plain = run(tiny, 0.7, tolerance=0.1)
    kw = dict(tolerance=0.1, episodes=10, max_edits=8, patience=3, seed=0, name="tiny")
    same = adapt_to_success(tiny, ShyExpert(home_of(tiny)), Pusher(3.0), 0.7, refresh=True, **kw)
    # where every draw agrees, the refreshed measurements repeat the measured ones: the same edits, more rollouts
    assert same.success_trace == plain.success_trace and same.measure_steps > plain.measure_steps
    assert same.to_dict()["refresh"] is True and plain.to_dict()["refresh"] is False
    # a gain on the measured draw alone is kept, but the house then measures 1.0 again on the refreshed draws, the
    # next edits are measured there, and the run reports that figure rather than the selected one
    noisy = adapt_to_success(tiny, ShyExpert(home_of(tiny), measured_only=True), Pusher(3.0), 0.7, **kw)
    fresh = adapt_to_success(tiny, ShyExpert(home_of(tiny), measured_only=True), Pusher(3.0), 0.7, refresh=True, **kw)
    assert noisy.success < 1.0 and fresh.edits and fresh.success == 1.0
    assert fresh.success_trace[1] < 1.0 and fresh.stopped.startswith("no kept edit")
    strides = {DRAW_SEED_STRIDE, FRESH_SEED_STRIDE, CONFIRM_SEED_STRIDE, REFRESH_SEED_STRIDE}
    assert len(strides) == 4 and all(x % 1000 == 0 for x in strides)


@pytest.mark.parametrize("draws", [0, 17, 1.5])
def test_a_bad_number_of_draws_is_refused(tiny, draws):
    with pytest.raises(ConfigError, match="draws"):
        adapt_to_success(tiny, ExpertPolicy(), Pusher(3.0), 0.5, episodes=2, name="tiny", draws=draws)


def test_an_episode_without_a_seed_draws_from_seed_zero():
    from dataclasses import replace as with_

    from adaptenv.adapt.target import FRESH_SEED_STRIDE, drawn
    from adaptenv.sim.task import Episode

    ep = Episode("Bed", (1.0, 2.0, 0.0), None)
    assert [e.seed for e in drawn([ep], 2, FRESH_SEED_STRIDE, first=1)] == [FRESH_SEED_STRIDE, 2 * FRESH_SEED_STRIDE]
    assert drawn([with_(ep, seed=5)], 2)[0].seed == 5


def test_a_stop_gap_below_the_tolerance_edits_on_past_the_tolerance_edge(tiny):
    """With a stop gap under the tolerance (by default half of it) the run goes on where the tolerance alone
    stopped it, the same edits first, until the gap is at most the stop gap; `reached` is still judged by the
    tolerance."""
    edge = run(tiny, 0.7, tolerance=0.2, stop_gap=0.2)
    default, deeper = run(tiny, 0.7, tolerance=0.2), run(tiny, 0.7, tolerance=0.2, stop_gap=0.0)
    assert edge.stopped == "within tolerance" and edge.gap > 0.1
    assert default.stopped == "within the stop gap 0.1" and default.gap <= 0.1 + 1e-9
    assert deeper.stopped == "within the stop gap 0" and deeper.gap == pytest.approx(0.0) and deeper.reached
    assert deeper.edits[:len(edge.edits)] == edge.edits and len(deeper.edits) > len(edge.edits)
    assert deeper.to_dict()["stop_gap"] == 0.0 and edge.to_dict()["stop_gap"] == 0.2
    assert default.to_dict()["stop_gap"] == pytest.approx(0.1)
    for bad in (0.3, -0.1, math.nan):
        with pytest.raises(ConfigError, match="stop gap must lie in"):
            adapt_to_success(tiny, ShyExpert(home_of(tiny)), Pusher(3.0), 0.7, tolerance=0.2, stop_gap=bad)


@pytest.mark.parametrize(("t", "expect"), [
    ({"reached": True, "fresh_draws": 3, "fresh_reached": True, "stopped": "within the stop gap 0.05"}, None),
    ({"reached": True, "fresh_draws": 0, "stopped": "within the stop gap 0.05"}, None),
    ({"reached": False, "fresh_draws": 3, "fresh_reached": False, "stopped": "edit budget used"}, "--steps"),
    ({"reached": False, "fresh_draws": 0, "stopped": "no kept edit in 6 rounds in a row"}, "out of reach"),
    ({"reached": True, "fresh_draws": 3, "fresh_reached": False, "stopped": "within the stop gap 0.05"},
     "--target-episodes"),
    ({"reached": True, "fresh_draws": 3, "fresh_reached": False, "stopped": "edit budget used"}, "--target-episodes"),
    ({"reached": False, "fresh_draws": 3, "fresh_reached": True, "stopped": "no kept edit in 6 rounds in a row"}, None),
])
def test_a_missed_target_names_what_to_try(t, expect):
    from adaptenv.cli.adapt import target_hint

    hint = target_hint(t)
    assert (hint is None) if expect is None else (expect in hint and "\n" not in hint)
