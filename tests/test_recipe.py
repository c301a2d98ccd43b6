"""Collection recipes: YAML files naming tasks and their settings."""

import pytest

from vintix.collect import CollectionError
from vintix.collect.recipe import load_recipe
from vintix.demonstrators.goal_blind import read_goal_blind
from vintix.demonstrators.trained import weights_paths
from vintix.tasks import get_task
from vintix.tasks.metaworld import GRIPPER_CENTRE_GOAL_TASKS
from vintix.train.config import load_config


def test_shipped_recipes_load():
    tiny = {plan.task: plan for plan in load_recipe("tiny")}
    assert tiny["button-press-v3"].schedule.curvature == 2.0 and tiny["reach-v3"].schedule.curvature == 1.0
    suite = load_recipe("metaworld-cpu")
    assert len(suite) == 45 and "door-lock-v3" not in {p.task for p in suite}  # test tasks stay out
    domains = {get_task(plan.task).domain for plan in load_recipe("multidomain-tiny")}
    assert domains == {"mujoco", "metaworld", "industrial_benchmark"}
    paper = {plan.task: plan for plan in load_recipe("paper")}
    assert len(paper) == 72 and {get_task(t).split for t in paper} == {"train"}
    assert (paper["Humanoid-v5"].histories, paper["Humanoid-v5"].steps) == (15, 1_000_000)  # Appendix G
    assert sum(p.histories * p.steps for p in paper.values()) == 191_500_000


@pytest.mark.parametrize("name", ["icrl-reach", "icrl-suite"])
def test_the_expert_distillation_recipe_of_an_icrl_recipe_plays_its_goals_with_the_goal_aware_expert(name):
    """The ED ablation must differ from AD only in who plays: the same hidden goals, lengths and seeds."""
    ad_plans, ed_plans = load_recipe(name), load_recipe(f"{name}-expert")
    assert [ad.task for ad in ad_plans] == [ed.task for ed in ed_plans]
    for ad, ed in zip(ad_plans, ed_plans, strict=True):
        assert (ad.behaviour, ed.behaviour) == ("probe-then-sample", "expert")
        last = ad.histories - 1
        assert [ed.recorded_settings(i)["env_seed"] for i in (0, last)] == \
            [ad.recorded_settings(i)["env_seed"] for i in (0, last)]
        assert (ed.histories, ed.steps, ed.aim) == (ad.histories, ad.steps, ad.aim)


def test_the_icrl_suite_holds_tasks_whose_hidden_goal_decides_success_and_selects_its_checkpoint_on_all_of_them():
    """Each task of the suite must be one a goal-blind expert mostly fails (the goal-blind table), played by
    the demonstrator that never sees the goal, its reach tasks as icrl-reach plays reach; checkpoint selection
    must score every one of them."""
    plans, table = load_recipe("icrl-suite"), read_goal_blind()
    (reach,) = load_recipe("icrl-reach")
    for plan in plans:
        row = table[plan.task]
        assert row.goal_blind_success <= 0.45 and row.true_goal_success == 1.0, plan.task
        assert plan.behaviour == "probe-then-sample", plan.task
        if plan.task in GRIPPER_CENTRE_GOAL_TASKS:
            assert (plan.aim, plan.probe_margin) == (reach.aim, reach.probe_margin) == ("gripper-centre", 0.06)
    assert load_config("icrl-suite").select_tasks == [plan.task for plan in plans]


def test_the_paper_recipe_fits_a_schedule_for_every_task_with_a_demonstrator():
    """A demonstrator shipped without fitting its task's schedule would collect with plain linear decay.
    Meta-World fits one per history (its goals answer noise differently), the others one per task."""
    for plan in load_recipe("paper"):
        spec = get_task(plan.task)
        if spec.domain == "metaworld":
            assert plan.schedule.pilot_steps > 0 and not plan.schedule.knots, plan.task
        else:
            assert bool(plan.schedule.knots) == weights_paths(spec.group)[1].is_file(), plan.task


def test_domains_expand_and_task_settings_override_defaults(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text("defaults: {histories: 3, steps: 500}\ntasks:\n  industrial_benchmark: {}\n"
                    "  industrial-benchmark-0-v1: {steps: 100, noise_free_fraction: 0.2}\n")
    plans = {p.task: p for p in load_recipe(path)}
    assert len(plans) == 21 and plans["industrial-benchmark-5-v1"].steps == 500
    assert plans["industrial-benchmark-0-v1"].steps == 100
    assert plans["industrial-benchmark-0-v1"].schedule.noise_free_fraction == 0.2


def test_unknown_setting_and_unknown_recipe_are_clear_errors(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text("tasks:\n  reach-v3: {stepz: 10}\n")
    with pytest.raises(ValueError, match="unknown setting.*stepz"):
        load_recipe(path)
    with pytest.raises(FileNotFoundError, match="shipped: .*tiny"):
        load_recipe("no-such-recipe")



@pytest.mark.parametrize(("text", "message"), [
    ("tasks:\n  reach-v3: {steps: 100}\n", "no histories"),
    ("defaults: {histories: 1}\ntasks:\n  reach-v3: {steps: many}\n", "CollectionPlan.steps must be int, got 'many'"),
    ("tasks:\n  reach-v3: {histories: 1, steps: 10, curvature: steep}\n", "NoiseSchedule.curvature must be float"),
    ("tasks:\n  reach-v3: 5\n", "must be mappings"),
    ("tasks: [reach-v3, : x\n", "not valid YAML"),
])
def test_a_recipe_with_missing_or_mistyped_settings_names_them(tmp_path, text, message):
    path = tmp_path / "r.yaml"
    path.write_text(text)
    with pytest.raises(CollectionError, match=message) as error:
        load_recipe(path)
    assert str(path) in str(error.value)


def test_the_meta_mujoco_recipe_holds_the_three_meta_rl_tasks_each_hidden_and_each_selected_on():
    """Each must be a task whose hidden parameter is worth return (the hidden-information table), played by the
    demonstrator that never sees it; selection scores return on all three, as they have no success flag."""
    plans, table, config = load_recipe("meta-mujoco"), read_goal_blind(), load_config("meta-mujoco")
    assert [plan.task for plan in plans] == ["HalfCheetah-Vel-v5", "HalfCheetah-Dir-v5", "Ant-Dir-v5"]
    for plan in plans:
        assert table[plan.task].hidden_return > 0.3, plan.task
        assert plan.behaviour == "probe-then-sample" and plan.target == "expert", plan.task
    assert config.select_tasks == [plan.task for plan in plans] and config.select_metric == "score"
