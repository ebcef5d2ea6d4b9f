"""The flange spec generates exactly the paper's Table 1 and Figure 8."""

from flange_data import ASSEMBLY_EDGES, TABLE1

from hrc_drake.tasks.graph import StateKind, UnknownStateError


def test_exactly_the_twenty_states_of_table1(flange_space):
    got = {
        flange_space.name(s): (flange_space.sequence(s), flange_space.state_kind(s).label)
        for s in range(flange_space.n_states)
    }
    assert got == TABLE1


def test_every_edge_of_figure8_with_its_undo(flange_space):
    graph = flange_space.to_networkx()
    seq = {name: s for name, (s, _) in TABLE1.items()}
    expected = set()
    for a, b in ASSEMBLY_EDGES:
        expected.add((seq[a], seq[b]))
        expected.add((seq[b], seq[a]))
    assert set(graph.edges) == expected
    for a, b in ASSEMBLY_EDGES:
        forward = graph.edges[seq[a], seq[b]]
        assert forward["task"] == seq[b][-1]
        assert forward["action"] == "ass" + seq[b][-1][0]
        back = graph.edges[seq[b], seq[a]]
        assert back["task"] == "undo" and back["action"] == "disass" and back["undo"]


def test_node_attributes(flange_space):
    graph = flange_space.to_networkx()
    start = graph.nodes[()]
    assert start["kind"] == "start" and start["name"] == "1"
    assert graph.nodes[("F1", "S23", "F03")]["configuration"] == frozenset({"F1", "S23", "F03"})


def test_states_11_and_17_share_a_configuration_but_not_a_state(flange_space):
    s11 = flange_space.index(("F3", "S12", "F01"))
    s17 = flange_space.index(("S12", "F01", "F3"))
    assert s11 != s17
    assert flange_space.configuration(s11) == flange_space.configuration(s17)


def test_merged_graph_has_sixteen_configurations(flange_space):
    merged = flange_space.to_merged_networkx()
    assert merged.number_of_nodes() == 16
    assert len(flange_space.configurations()) == 16
    assert sorted(merged.nodes[frozenset({"F3", "S12", "F01"})]["names"]) == ["11", "17"]
    assert merged.nodes[frozenset({"F2"})]["kind"] == "dead end"


def test_wrong_and_dead_end_states_offer_only_undo(flange_space):
    for s in range(flange_space.n_states):
        if flange_space.kind[s] in (StateKind.WRONG, StateKind.DEAD_END):
            assert [t for t, _ in flange_space.tasks(s)] == ["undo"]


def test_unknown_state_is_a_clear_error(flange_space):
    try:
        flange_space.index(("F1", "F2"))
    except UnknownStateError as err:
        assert "not a state of assembly 'flange'" in str(err)
    else:
        raise AssertionError("an unknown sequence must raise")
