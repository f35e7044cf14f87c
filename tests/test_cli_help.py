"""The top-level help is built without importing the commands, and says what the full
parser says."""

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


def test_top_level_help_imports_no_command():
    code = ("import sys\n"
            "from granular_material.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit as exc:\n    assert exc.code == 0\n"
            "heavy = [m for m in ('warp', 'matplotlib', 'scipy.stats', 'skfem', 'pandas',\n"
            "         'granular_material.dem', 'granular_material_reproduction')\n"
            "         if m in sys.modules]\n"
            "print('HEAVY', heavy)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert "HEAVY []" in run.stdout and "single-element" in run.stdout


def test_one_command_imports_no_other():
    """A command's parser (its help, its run) is built without the other commands: a core
    command imports no plugin, a plugin command no other plugin."""
    code = ("import sys\n"
            "from granular_material.cli import main\n"
            "for argv in (['prepare', '--help'], ['fractal', '--help']):\n"
            "    try:\n        main(argv)\n    except SystemExit as exc:\n"
            "        assert exc.code == 0\n"
            "others = [m for m in ('granular_material_reproduction',\n"
            "          'granular_material_validation', 'granular_material.cli.fem',\n"
            "          'granular_material.cli.scene', 'granular_material.cli.study')\n"
            "          if m in sys.modules]\n"
            "print('OTHERS', others)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert "OTHERS []" in run.stdout and "--particles" in run.stdout


def test_one_command_parser_is_that_of_the_full_parser():
    full = build_parser()
    for argv in (["biaxial", "--steps", "3", "--shards", "1"], ["prepare", "--batch", "2"]):
        assert vars(build_parser(argv[0]).parse_args(argv)) == vars(full.parse_args(argv))
