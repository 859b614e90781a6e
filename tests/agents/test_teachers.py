"""The shipped pi_0 against its teacher's labels: it agrees on the states it was trained on, not on its own.

This is why PPO's imitation term (``bc_coef`` with the expert's labels) pulls a warm-started policy
away from what it does: on the states pi_0 visits itself, the expert mostly says "turn towards the
target", which the agent cannot see (docs/agent.md, "PPO").
"""

from __future__ import annotations

import pytest

from adaptenv.agents.checkpoint import load_checkpoint
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.registry import init_checkpoint
from adaptenv.agents.teachers import label_agreement, make_teacher
from adaptenv.errors import ConfigError
from adaptenv.sim.vector import BatchSim


@pytest.mark.slow
def test_pi0_agrees_with_the_expert_on_expert_states_but_not_on_its_own():
    net = load_checkpoint(init_checkpoint("pretrained-scan")).net.eval()
    worlds = load_house_set("preset:pretrain-train").worlds
    on_expert = label_agreement(net, worlds, beta=1.0, envs=32, steps=96)
    on_own = label_agreement(net, worlds, beta=0.0, envs=32, steps=96)
    # what it was trained on (beta 1 -> 0.8): well below the 1.95 nats of a uniform guess
    assert on_expert.cross_entropy < 1.2 and on_expert.accuracy > 0.55
    # its own states: the expert's labels turn towards a target the agent has not seen
    assert on_own.cross_entropy > on_expert.cross_entropy + 0.5 and on_own.accuracy < on_expert.accuracy - 0.2
    assert on_own.label_share[0] < on_expert.label_share[0] / 2  # "move ahead" labels


def test_unknown_teacher_is_a_config_error(tiny_set):
    with pytest.raises(ConfigError, match="--teacher 'oracle'"):
        make_teacher("oracle", BatchSim(tiny_set.worlds))
