"""Issue 9, class 9: --quality means its level; options the user did not give never override it."""

from clsky import ScatteringTable
from clsky.quality import QUALITY_LEVELS

import forked_cli


def clsky(*args, cwd):
    return forked_cli.run("clsky", *args, cwd=cwd)


SMALL = ("--size", "4", "8", "4", "--orders", "2", "--gather-steps", "8", "4", "--progress", "none")


def test_quality_alone_gives_the_levels_mode_and_settings(tmp_path):
    result = clsky("table", "--quality", "high", *SMALL, "-o", "high.npz", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    settings = ScatteringTable.load(tmp_path / "high.npz").settings
    level = QUALITY_LEVELS["high"].table
    assert settings.mode == level.mode == "physical"
    assert "mode physical" in result.stdout
    for field in ("view_steps", "sun_steps", "multiple_view_steps", "order_tolerance", "transmittance_size"):
        assert getattr(settings, field) == getattr(level, field), field


def test_an_explicit_option_still_wins(tmp_path):
    result = clsky("table", "--quality", "high", "--mode", "atmosphere-plus", "--view-steps", "7", *SMALL,
                   "-o", "mixed.npz", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    settings = ScatteringTable.load(tmp_path / "mixed.npz").settings
    assert settings.mode == "atmosphere-plus" and settings.view_steps == 7
    assert settings.sun_steps == QUALITY_LEVELS["high"].table.sun_steps


def test_without_quality_the_defaults_hold(tmp_path):
    result = clsky("table", *SMALL, "-o", "plain.npz", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert ScatteringTable.load(tmp_path / "plain.npz").settings.mode == "atmosphere-plus"


def test_animate_options_not_given_keep_the_config_defaults():
    """animate's --preset, --mode and --error-budget default to None: the AnimationConfig decides."""
    from clsky.anim import cli
    from clsky.anim.animate import AnimationConfig
    from clsky.cli import build_parser

    parser, _ = build_parser((cli.register,))
    args = parser.parse_args(["animate", "--quality", "high"])
    assert (args.preset, args.mode, args.error_budget) == (None, None, None)
    config = cli._config(args)
    default = AnimationConfig()
    assert (config.preset, config.mode, config.error_budget, config.quality) == \
        (default.preset, default.mode, default.error_budget, "high")
    # (the atmosphere-plus scheme needs a black ground: the physical preset's 0.1 is set to 0)
    args = parser.parse_args(["animate", "--mode", "atmosphere-plus", "--ground-albedo", "0", "--error-budget", "0.2"])
    config = cli._config(args)
    assert (config.mode, config.error_budget, config.ground_albedo) == ("atmosphere-plus", 0.2, 0.0)
