"""The top-level help is built without importing the commands, and says what the full
parser says."""

import ast
import subprocess
import sys

from granular_material.cli import COMMAND_HELP, build_parser, command_parser


def _commands(parser):
    action = next(a for a in parser._actions if a.dest == "command")
    return [(choice.dest, choice.help) for choice in action._choices_actions]


def test_light_help_lists_the_commands_of_the_full_parser():
    full = _commands(build_parser())
    assert _commands(command_parser()) == full
    assert {name for name, _ in full} <= set(COMMAND_HELP)


def _modules_loaded_by_help(argvs: list[list[str]], modules: tuple[str, ...]
                            ) -> tuple[list[str], str]:
    """Which of ``modules`` a fresh interpreter has imported after ``main(argv)`` for each
    of ``argvs`` (each a help, exiting 0), and what they printed."""
    code = ("import sys\n"
            "from granular_material.cli import main\n"
            f"for argv in {argvs!r}:\n"
            "    try:\n        main(argv)\n    except SystemExit as exc:\n"
            "        assert exc.code == 0\n"
            f"print('LOADED', [m for m in {modules!r} if m in sys.modules])\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    printed, _, loaded = run.stdout.rpartition("LOADED ")
    return ast.literal_eval(loaded), printed


def test_top_level_help_imports_no_command():
    loaded, printed = _modules_loaded_by_help(
        [["--help"]], ("warp", "matplotlib", "scipy.stats", "skfem", "pandas",
                       "granular_material.dem", "granular_material_reproduction"))
    assert loaded == [] and "single-element" in printed


def test_one_command_imports_no_other():
    """A command's parser (its help, its run) is built without the other commands: a core
    command imports no plugin, a plugin command no other plugin."""
    loaded, printed = _modules_loaded_by_help(
        [["prepare", "--help"], ["fractal", "--help"]],
        ("granular_material_reproduction", "granular_material_validation",
         "granular_material.cli.fem", "granular_material.cli.scene",
         "granular_material.cli.study"))
    assert loaded == [] and "--particles" in printed


def test_one_command_parser_is_that_of_the_full_parser():
    full = build_parser()
    for argv in (["biaxial", "--steps", "3", "--shards", "1"], ["prepare", "--batch", "2"]):
        assert vars(build_parser(argv[0]).parse_args(argv)) == vars(full.parse_args(argv))


def test_run_gets_every_command_for_its_scenes():
    """A scene names any command, so ``run`` is built with all of them."""
    action = next(a for a in build_parser("run")._actions if a.dest == "command")
    assert set(action.choices) == set(next(
        a for a in build_parser()._actions if a.dest == "command").choices)


def test_the_stored_help_is_the_parsers_own():
    """Each command's --help and --help-all are printed from text stored in the package;
    it must be what the parsers print (regenerate: python -m
    granular_material.cli.stored_help)."""
    from granular_material.cli.help_texts import HELP_TEXTS
    from granular_material.cli.stored_help import generate

    assert generate() == HELP_TEXTS, "run python -m granular_material.cli.stored_help"


def test_a_commands_help_imports_nothing_it_runs_with():
    heavy = ("numpy", "warp", "skfem", "pandas", "scipy", "matplotlib",
             "granular_material.dem", "granular_material.cli.fem")
    loaded, printed = _modules_loaded_by_help(
        [["biaxial", "--help"], ["run", "-h"], ["prepare", "--steps", "3", "--help"],
         ["single-element", "--help-all"]], heavy)
    assert loaded == [] and "--help-all" in printed and "--tangent" in printed


def test_help_shows_the_first_options_and_names_the_others():
    short = build_parser("biaxial").commands["biaxial"].format_help()
    full = build_parser("biaxial").commands["biaxial"].format_help_all()
    assert len(short.splitlines()) < 100 < len(full.splitlines())
    for shown in ("--steps", "--out", "--material", "--rve", "--resume", "Newton solver (",
                  "RVE material ("):
        assert shown in short, shown
    for hidden in ("--tangent", "--rtol", "--kt-over-kn", "--shards"):
        assert hidden not in short and hidden in full, hidden
