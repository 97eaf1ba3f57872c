"""One config dialect for train.py and search.py (billiards.app_config): typed schemas per
group option, registered at import side by side, the proposers as one config parametrised by
name, saved configs of every form loading, one spelling of the paradigms, one repo-path rule."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

import billiards.rl.config as train_config
import billiards.search.config as search_config
from billiards.files import ROOT, repo_path

REPO = Path(__file__).resolve().parents[2]


def compose_search(*overrides: str):
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        return compose("search", overrides=list(overrides))


def group_options(group: str) -> list[str]:
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        return sorted(GlobalHydra.instance().config_loader().get_group_options(group))


# ----------------------------------------------------------------------------- per-option schemas


@pytest.mark.slow
@pytest.mark.parametrize("overrides,key,schema", [
    (["search=h2", "search.c_puct=5"], "c_puct", "H2Config"),
    (["search=puct", "search.k1=50"], "k1", "PUCTConfig"),
    (["protocol=p3", "protocol.n_innings=5"], "n_innings", "P3Config"),
    (["protocol=p1", "protocol.cap=5"], "cap", "P1Config"),
    (["proposer=geometric", "proposer.checkpoints=[a.pt]"], "checkpoints", "GeometricProposerConfig"),
    (["proposer=base", "proposer.power_low=0.2"], "power_low", "PolicyProposerConfig"),
])
def test_a_knob_of_another_option_fails_while_composing(overrides, key, schema):
    with pytest.raises(ConfigCompositionException) as err:
        compose_search(*overrides)
    assert f"Key '{key}' not in '{schema}'" in str(err.value.__cause__)


@pytest.mark.slow
def test_each_option_takes_its_own_knobs():
    cfg = compose_search("search=puct", "search.c_puct=5", "protocol=p1", "protocol.n_innings=3")
    assert cfg.search.c_puct == 5.0 and cfg.protocol.n_innings == 3
    assert OmegaConf.get_type(cfg.search) is search_config.PUCTConfig
    assert OmegaConf.get_type(cfg.protocol) is search_config.P1Config
    search_config.validate(cfg)
    assert search_config.option("search", cfg.search).settings().c_puct == 5.0
    cfg = compose_search("search=h2", "search.k1=100", "search.m1=3", "search.budget=400")
    h2 = search_config.option("search", cfg.search).settings()
    assert (h2.k1, h2.m1, h2.k2) == (100, 3, 100)


@pytest.mark.slow
def test_appended_keys_and_contradicting_kinds_fail_validation():
    """``+key=value`` appends even to a closed node; validation catches it (and a kind that
    contradicts the chosen option) before anything runs."""
    for overrides, message in [
        (["search=h2", "+search.c_puct=5"], "search.c_puct: not a key of H2Config (search=h2 takes kind, budget, gamma, foul_penalty, k1"),
        (["+foo=1"], "foo: not a key of SearchAppConfig"),
        (["search=h2", "search.kind=puct"], "search.kind='puct' contradicts search=h2"),
        (["protocol=p1", "protocol.name=p3"], "protocol.name='p3' contradicts protocol=p1"),
    ]:
        with pytest.raises(search_config.SearchConfigError, match="invalid search config") as err:
            search_config.validate(compose_search(*overrides))
        assert message in str(err.value), (overrides, str(err.value))


def _noise_for(search: str) -> str:
    """The noise a search option is written for: for_noise_<noise> and deep_<noise> name theirs,
    h2 and puct play exact, robust needs one."""
    for prefix in ("for_noise_", "deep_"):
        if search.startswith(prefix):
            return search.removeprefix(prefix)
    return "fastfiz" if search == "robust" else "none"


@pytest.mark.parametrize("search", group_options("search"))
def test_every_search_option_composes_and_validates_under_its_noise(search):
    """Each file of conf/search composes and passes the app's checks (the value file it names is
    there and loads, its screen fits its budget), over the cheap geometric proposer."""
    noise = _noise_for(search)
    assert noise in group_options("noise"), (search, noise)
    cfg = compose_search(f"search={search}", f"noise={noise}", "proposer=geometric")
    assert search_config.errors(cfg) == []
    s = cfg.search
    if s.kind == "robust":
        assert s.target <= s.k1 <= s.budget
    if search.startswith("deep_"):  # more simulations than the noise's default, the same value and weight
        default = compose_search(f"search=for_noise_{noise}", f"noise={noise}", "proposer=geometric").search
        assert s.budget > default.budget and (s.value, s.position) == (default.value, default.position)


def test_option_groups_list_only_real_options():
    """The schemas live under schema/, outside the option groups (no ``search_schema`` option)."""
    # for_noise_<noise>: the default search per execution noise (h2 without noise, robust with it);
    # deep_fastfiz_x5: fastfiz_x5's at 2,400 simulations
    assert group_options("search") == ["deep_fastfiz_x5", "for_noise_fastfiz", "for_noise_fastfiz_x5", "for_noise_none",
                                       "for_noise_variable", "h2", "puct", "robust"]
    assert group_options("protocol") == ["p1", "p3", "p3_paper"]
    # for_noise_<noise>: each noise's shot proposer; default_for_<noise>: search.py's default proposer
    assert group_options("proposer") == ["base", "both", "default_for_fastfiz", "default_for_fastfiz_x5", "default_for_none",
                                         "default_for_variable", "exit", "exit_x5", "exit_x5_mixed", "for_noise_fastfiz",
                                         "for_noise_fastfiz_x5", "for_noise_none", "for_noise_variable", "forgiving", "gentle",
                                         "geometric", "mixed", "near_miss", "policy", "ranked", "ranked_exact",
                                         "ranked_exact_small"]
    assert group_options("noise") == ["fastfiz", "fastfiz_x5", "none", "variable"]
    assert group_options("algo") == ["exit", "ppo", "ppo_paper", "sac", "sac_paper", "td3", "td3_paper"]
    assert not (REPO / "conf" / "proposer").exists()  # one proposer config, parametrised by name


# ----------------------------------------------------------------------------- proposers


# proposer=<name>: the campaign's Table 5 ensemble of that shaping, its command the campaign's
SHAPING_OF = {"base": "foul_penalty", "gentle": "gentle", "near_miss": "near_miss", "both": "both"}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SHAPING_OF))
def test_a_shipped_proposer_by_name_is_the_campaigns_table5_ensemble(name):
    import shlex

    from billiards.tables import paper_tables

    cfg = compose_search(f"proposer={name}")
    node = OmegaConf.to_container(cfg.proposer)
    assert {k: node[k] for k in ("kind", "name", "checkpoints")} == {
        "kind": "policy", "name": name, "checkpoints": [f"results/policies/{name}/seed{s}.pt" for s in range(3)]}
    train, export = node["command"].split(" && ")
    assert export == f"python -m billiards.rl.policy export <the three run dirs> --out results/policies/{name}"
    words = shlex.split(train)
    # the command is the Table 5 stage's sweep for this row, the three seeds of its files
    table5 = paper_tables()["table5"]
    assert words == ["python", "train.py", "-m", "experiment=table5", f"variant=table5/{SHAPING_OF[name]}", "seed=0,1,2"]
    assert f"table5/{SHAPING_OF[name]}" in table5.sweep["variant"] and table5.seeds == [0, 1, 2]
    # ... and Table 6 searches these files by name
    assert name in paper_tables()["table6"].sweep["proposer"]
    assert paper_tables()["table6"].rows[name].trained_from == f"table5/{SHAPING_OF[name]}"
    search_config.validate(cfg)  # the shipped files are there


@pytest.mark.slow
def test_the_shipped_proposers_were_trained_as_their_command_says():
    """Each shipped file's saved training config is the campaign's Table 5 run of its shaping and
    seed, on the paper's table, for 1M steps; so on the default table nothing warns."""
    import warnings

    from billiards.files import load_tagged
    from billiards.physics.config import PhysicsMismatchWarning
    from billiards.rl.checkpoint import CheckpointError
    from billiards.rl.policy import POLICY_FORMAT
    from billiards.search.proposers import load_policy_proposer

    for name, shaping in SHAPING_OF.items():
        paths = [ROOT / f"results/policies/{name}/seed{s}.pt" for s in range(3)]
        for s, path in enumerate(paths):
            state = load_tagged(path, POLICY_FORMAT, CheckpointError, "exported policy")
            run = OmegaConf.create(state["config"])
            assert (run.seed, run.physics.preset, run.env.constrain_aim, run.env.extra_features) == (s, "korean_medium", True, True)
            assert (run.shaping.name, run.algo.name, run.budget.total_steps) == (shaping, "sac", 1_000_000), (name, s)
            assert state["summary"]["frames"] == 1_000_000 and state["eval"]["n_innings"] == 100
        with warnings.catch_warnings():
            warnings.simplefilter("error", PhysicsMismatchWarning)
            load_policy_proposer(paths, name=name)


@pytest.mark.slow
def test_geometric_proposer_and_a_missing_checkpoint():
    cfg = compose_search()
    assert OmegaConf.to_container(cfg.proposer) == {"kind": "geometric", "name": "geometric", "power_low": 0.15,
                                                     "power_high": 0.9, "u_low": 0.0, "u_high": 1.0,
                                                     "spin_low": -1.0, "spin_high": 1.0, "far_share": 0.0}
    cfg = compose_search("proposer=near_miss", "proposer.checkpoints=[nowhere/seed0.pt]")
    with pytest.raises(search_config.SearchConfigError, match=r"proposer 'near_miss': no checkpoint at nowhere/seed0.pt "
                                                               r"\(trained with: python train.py"):
        search_config.validate(cfg)
    with pytest.raises(search_config.SearchConfigError, match="proposer 'policy' is a policy ensemble but lists no checkpoints"):
        search_config.validate(compose_search("proposer=policy"))
    mine = compose_search("proposer=policy", "proposer.checkpoints=[results/policies/gentle/seed1.pt]", "proposer.name=mine")
    search_config.validate(mine)
    assert OmegaConf.get_type(mine.proposer) is search_config.PolicyProposerConfig and mine.proposer.command is None


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_a_mixed_proposer_shares_the_candidates_between_a_policy_and_a_ranker():
    """proposer=mixed: its policy and ranker nodes are the policy and ranked options' own
    schemas (checked alike), the share lies in [0, 1], and it builds the mixture the config
    describes: the policy's ceil(share * k) candidates first, then the ranker's."""
    import numpy as np

    from billiards.physics import DEFAULT_PARAMS
    from billiards.search.run import make_proposer

    with pytest.raises(search_config.SearchConfigError, match="proposer 'policy' is a policy ensemble but lists no checkpoints"):
        search_config.validate(compose_search("noise=fastfiz", "proposer=mixed"))
    policy = "proposer.policy.checkpoints=[results/policies/exit/seed0.pt]"
    with pytest.raises(search_config.SearchConfigError, match=r"proposer.share must lie in \[0, 1\], got 1.5"):
        search_config.validate(compose_search("noise=fastfiz", "proposer=mixed", policy, "proposer.share=1.5"))
    with pytest.raises(search_config.SearchConfigError, match="proposer 'ranked': no ranker file at nowhere.pt"):
        search_config.validate(compose_search("noise=fastfiz", "proposer=mixed", policy, "proposer.ranked.ranker=nowhere.pt"))
    with pytest.raises(Exception, match="c_puct"):
        compose_search("noise=fastfiz", "proposer=mixed", "proposer.c_puct=1")
    cfg = compose_search("noise=fastfiz", "proposer=mixed", policy, "proposer.share=0.25", "proposer.ranked.pool=100")
    search_config.validate(cfg)
    mixed = make_proposer(cfg.proposer, DEFAULT_PARAMS)
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    positions = Billiards4BallVectorEnv(3, start="random").reset(seed=2)[1]["positions"]
    got = mixed.propose(positions, 8, np.random.default_rng(4))
    check = np.random.default_rng(4)
    want = np.concatenate([mixed.first.propose(positions, 2, check), mixed.second.propose(positions, 6, check)], axis=1)
    assert got.shape == (3, 8, 4) and np.array_equal(got, want)
    assert mixed.first.name == "policy" and mixed.second.pool == 100 and mixed.share == 0.25


# ----------------------------------------------------------------------------- saved configs


def shipped_search_results() -> list[Path]:
    return sorted((REPO / "results" / "search").rglob("*.json"))


@pytest.mark.slow
def test_every_shipped_search_result_config_loads(tmp_path):
    """results/search/*.json hold configs of the former union form (every group's node with
    every option's keys), some from before the physics presets: each loads as a run's saved
    config and rebuilds the same search, proposer, protocol and table."""
    from billiards.search.settings import H2Config, PUCTConfig

    files = shipped_search_results()
    assert len(files) >= 20
    forms = set()
    for i, path in enumerate(files):
        old = json.loads(path.read_text())["config"]
        forms.add(("physics" in old, "c_puct" in old["search"], "checkpoints" in old["proposer"]))
        run = tmp_path / str(i)
        run.mkdir()
        (run / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.create(old)))
        cfg = search_config.saved_config(run)
        search_config.validate(cfg)
        s = old["search"]
        expected = (H2Config.from_budget(s["budget"], s["k1"], s["m1"], gamma=s["gamma"], foul_penalty=s["foul_penalty"])
                    if s["kind"] == "h2" else
                    PUCTConfig(**{k: s[k] for k in ("budget", "c_puct", "pw_c", "pw_alpha", "pool", "max_depth", "gamma",
                                                    "foul_penalty")}))
        assert search_config.option("search", cfg.search).settings() == expected, path
        assert cfg.proposer.name == old["proposer"]["name"] and cfg.protocol.name == old["protocol"]["name"]
        if old["proposer"]["kind"] == "policy":
            assert list(cfg.proposer.checkpoints) == old["proposer"]["checkpoints"]
        for key in ("seeds", "cap") if old["protocol"]["name"] == "p3" else ("n_innings", "shots"):
            assert cfg.protocol[key] == old["protocol"][key]
        assert cfg.physics.preset == old.get("physics", {"preset": "international"})["preset"]
    assert (False, True, True) in forms and (True, True, True) in forms  # pre-preset and preset-era union forms

    bad = dict(old, search={**old["search"], "c_pcut": 2.0})  # a key no form ever had
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.create(bad)))
    with pytest.raises(search_config.SearchConfigError, match="c_pcut"):
        search_config.saved_config(tmp_path / "bad")


@pytest.mark.slow
def test_a_picture_of_a_search_run_saved_in_the_former_form(tmp_path):
    from billiards import pictures
    from billiards.physics import PRESETS

    old = json.loads((REPO / "results" / "search" / "korean_medium" / "geometric_puct_p1.json").read_text())["config"]
    (tmp_path / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.create(old)))
    actor, constrain_aim, extra_features, made_on = pictures.load_player(str(tmp_path))
    assert type(actor).__name__ == "PUCTActor" and actor.cfg.budget == old["search"]["budget"]
    assert made_on == PRESETS["korean_medium"] and not constrain_aim and not extra_features


# ----------------------------------------------------------------------------- registration


@pytest.mark.slow
def test_both_apps_register_side_by_side():
    """Importing each app's config module registers its schema (distinct names) and the
    resolvers; both compose in one process, in either order."""
    assert train_config.TrainConfig.__name__ == "TrainConfig" and train_config.Config is train_config.TrainConfig
    assert search_config.SearchAppConfig.__name__ == "SearchAppConfig"
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        search = compose("search", overrides=["resume=null"])
        train = compose("config", overrides=["algo=td3"])
        again = compose("search", overrides=["search=puct"])
    assert OmegaConf.get_type(train.algo) is train_config.TD3Config and train.env.paradigm == train_config.Paradigm.random_continue
    assert search.proposer.name == "geometric" and again.search.kind == "puct"
    # the resolvers both apps' hydra.run.dir use
    assert OmegaConf.create({"a": None, "b": "${billiards.or:${a},x}"}).b == "x"


def test_the_algorithms_are_listed_once():
    """ALGO_SCHEMAS is the one list of algorithms: the agents, the off-policy ones, validate's
    and the checkpoint's messages follow it; every algorithm's schema declares the shared keys
    through AlgoConfig; train.py's callback is the apps' ValidatingCallback."""
    from billiards.app_config import ValidatingCallback
    from billiards.rl.learners import AGENTS, OFF_POLICY
    from billiards.rl.checkpoint import config_problem

    schemas = train_config.ALGO_SCHEMAS
    assert list(AGENTS) == list(schemas) and OFF_POLICY == train_config.OFF_POLICY == ("sac", "td3")
    assert all(issubclass(s, train_config.AlgoConfig) for s in schemas.values())
    assert config_problem({"algo": {"name": "dqn"}, "env": {}}) == \
        "config.algo.name='dqn': not an algorithm of this version (sac, td3, ppo, exit)"
    from billiards.rl.validation import ValidateConfig

    assert issubclass(ValidateConfig, ValidatingCallback)


# ----------------------------------------------------------------------------- one spelling, one path rule


def test_one_spelling_of_the_paradigms():
    from billiards.envs import PARADIGMS, make_env

    assert sorted(PARADIGMS) == sorted(p.value for p in train_config.Paradigm)
    assert train_config.env_paradigm(train_config.Paradigm.canonical_reset) == "canonical_reset"
    assert train_config.env_paradigm("random_continue") == "random_continue"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = make_env(2, paradigm="canonical_reset")
    assert (env.base_env.start, env.base_env.on_miss) == ("canonical", "reset")
    with pytest.warns(DeprecationWarning, match="'canonical-reset' is spelt 'canonical_reset' now"):
        old = make_env(2, paradigm="canonical-reset")
    assert (old.base_env.start, old.base_env.on_miss) == ("canonical", "reset")
    with pytest.raises(ValueError, match="paradigm must be one of"):
        make_env(2, paradigm="canonical reset")


def test_repo_path_is_the_one_rule(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert repo_path("results/policies/base/seed0.pt") == ROOT / "results/policies/base/seed0.pt"
    (tmp_path / "mine.pt").write_bytes(b"x")
    assert repo_path("mine.pt") == Path("mine.pt")  # the working directory first
    assert repo_path(tmp_path / "elsewhere.pt") == tmp_path / "elsewhere.pt"
    assert train_config.resolve_rm_model("results/rm/model.pt") == ROOT / "results/rm/model.pt"
    cfg = search_config.option("proposer", {"kind": "policy", "name": "p", "checkpoints": ["mine.pt", "results/x.pt"]})
    assert cfg.paths() == ["mine.pt", str(ROOT / "results/x.pt")]


@pytest.mark.slow
def test_each_apps_help_lists_its_own_groups_and_fixed_choices():
    from conftest import app_here

    def help_of(app):
        out = app_here(app, "--help", cwd=REPO)
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout

    train, search = help_of("train.py"), help_of("search.py")
    assert "algo: exit, ppo, ppo_paper, sac, sac_paper, td3, td3_paper" in train and "shaping: " in train
    assert "env.paradigm: canonical_reset, canonical_continue, random_reset, random_continue" in train
    assert "\nprotocol:" not in train and "\nproposer:" not in train and "schema" not in train.split("== Config")[0]
    assert "proposer: " in search and "protocol: p1, p3" in search and "\nalgo:" not in search.split("== Config")[0]
    # each app's own paper-table presets; a table's rows as variant=<table>/<row>
    def groups(text):
        return {line.split(": ")[0]: line.split(": ", 1)[1].split(", ") for line in text.split("== Config")[0].splitlines()
                if ": " in line and not line.startswith(" ")}

    assert "table4" in groups(train)["experiment"] and "table6" not in groups(train)["experiment"]
    assert "table4/aim_features" in groups(train)["variant"] and "table3/staged" in groups(train)["variant"]
    assert groups(search)["experiment"] == ["table6"]


@pytest.mark.slow
def test_train_refuses_search_apps_preset_at_once(tmp_path):
    from conftest import app_here

    out = app_here("train.py", "experiment=table6", cwd=tmp_path)
    assert out.returncode != 0 and "experiment=table6 is a search.py preset: python search.py -m experiment=table6" in out.stderr
    assert not (tmp_path / "outputs").exists()


@pytest.mark.slow
def test_under_noise_the_default_is_the_strongest_measured_configuration():
    """``python search.py noise=<preset>`` with no proposer or search named plays the
    position-aware robust search (the shipped table value) over the shot ranker trained for
    that noise, from a pool of 500 (under fastfiz_x5 and variable sharing the candidates with
    the fastfiz_x5 expert-iteration policy); without noise, h2 over geometric draws, as before;
    either stays one override away, and ``proposer=for_noise_<preset>`` is the shot ranker alone."""
    first, run = "results/values/value.pt", "results/values/run1.pt"  # P(next shot scores); the discounted run
    for noise, (proposer, ranker, pool, search, position, value) in {
            "none": ("geometric", None, None, "h2", None, None),
            "fastfiz": ("ranked", "results/rankers/fastfiz/ranker.pt", 500, "robust", 8.0, run),
            "fastfiz_x5": ("mixed", "results/rankers/fastfiz_x5/ranker.pt", 500, "robust", 3.0, first),
            "variable": ("mixed", "results/rankers/fastfiz_x5/ranker.pt", 500, "robust", 5.0, first)}.items():
        cfg = compose_search(f"noise={noise}")
        ranked = cfg.proposer.ranked if proposer == "mixed" else cfg.proposer
        got = (cfg.proposer.kind, ranked.get("ranker"), ranked.get("pool"), cfg.search.kind, cfg.search.get("position"))
        assert got == (proposer, ranker, pool, search, position), noise
        if proposer == "mixed":  # the fastfiz_x5 expert-iteration policy proposes half of each wave
            assert (cfg.proposer.name, cfg.proposer.share) == ("exit_x5_mixed", 0.5)
            assert list(cfg.proposer.policy.checkpoints) == ["results/policies/exit_x5/seed0.pt"]
        shot = compose_search(f"noise={noise}", f"proposer=for_noise_{noise}").proposer  # the shot proposer alone
        assert (shot.kind, shot.get("ranker"), shot.get("pool")) == ({"none": "geometric"}.get(noise, "ranked"), ranker, pool)
        assert cfg.search.get("value") == value
        assert cfg.search.get("target") == {"none": None, "fastfiz": 40}.get(noise, 10)  # the adaptive screen's stop
        search_config.validate(cfg)  # the ranker and value files are there and load
    blind = compose_search("noise=fastfiz", "search=robust", "proposer=ranked")  # the recorded commands' search
    assert (blind.search.position, blind.search.value, blind.proposer.pool) == (0.0, None, 2000)
    older = compose_search("noise=fastfiz", "proposer=geometric", "search=h2")
    assert (older.proposer.kind, older.search.kind) == ("geometric", "h2")
