"""Reproduce lines: quoted, flags only when set, and parsed back by the real parser."""

from conftest import parse_reproduce

from common.cases import DEFAULT_MATERIALS
from common.reproduce import command, material_option, mesh_option, states_option
from common.states import state_names


def test_command_quotes_and_leaves_defaults_out():
    line = command("dma", quick=True, cells=None, frequencies=3, amplitude=False)
    assert line == "mjed-verify dma --quick --frequencies 3"
    line = command("equivalence", material="NeoHookean", mesh="/tmp/my organ.vtu", states="rest")
    assert parse_reproduce(line)["mesh"] == "/tmp/my organ.vtu"
    assert command("equivalence", prefix=("mpirun", "-n", "2"), mesh="x").startswith(
        "mpirun -n 2 mjed-verify"
    )


def test_options_spell_all_only_for_the_full_default_sets():
    assert material_option(DEFAULT_MATERIALS.values()) == ("all", "")
    assert material_option([DEFAULT_MATERIALS["Ogden"], DEFAULT_MATERIALS["Costa"]]) == (
        "Ogden,Costa",
        "",
    )
    assert mesh_option(["single-tet", "cube-small", "cube-paper"]) == "all"
    assert mesh_option(["cube-paper", "single-tet"]) == "cube-paper,single-tet"
    assert states_option(list(state_names())) == "all"
    six = ["rest", "uniaxial", "compression", "shear", "triaxial", "random"]  # not every state
    assert states_option(six) == ",".join(six)
    assert states_option(["random"]) == "random"
