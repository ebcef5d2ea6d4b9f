"""The flange case as test data (the paper's Table 1 and Figure 8; see docs/flange-case.md)."""

TABLE1 = {
    "1": ((), "start"),
    "2": (("F1",), "normal"),
    "3": (("F2",), "dead end"),
    "4": (("F3",), "normal"),
    "5": (("S12",), "normal"),
    "6": (("S23",), "normal"),
    "7": (("F1", "S23"), "normal"),
    "8": (("F3", "S12"), "normal"),
    "9": (("F1", "S23", "F02"), "wrong"),
    "10": (("F1", "S23", "F03"), "terminal"),
    "11": (("F3", "S12", "F01"), "terminal"),
    "12": (("F3", "S12", "F02"), "wrong"),
    "13": (("S12", "F01"), "normal"),
    "14": (("S12", "F02"), "normal"),
    "15": (("S23", "F02"), "normal"),
    "16": (("S23", "F03"), "normal"),
    "17": (("S12", "F01", "F3"), "terminal"),
    "18": (("S12", "F02", "F3"), "wrong"),
    "19": (("S23", "F02", "F1"), "wrong"),
    "20": (("S23", "F03", "F1"), "terminal"),
}

# Figure 8's assembly edges; each also has its reverse "disassemble" edge.
ASSEMBLY_EDGES = [
    ("1", "2"),
    ("1", "3"),
    ("1", "4"),
    ("1", "5"),
    ("1", "6"),
    ("2", "7"),
    ("4", "8"),
    ("5", "13"),
    ("5", "14"),
    ("6", "15"),
    ("6", "16"),
    ("7", "9"),
    ("7", "10"),
    ("8", "11"),
    ("8", "12"),
    ("13", "17"),
    ("14", "18"),
    ("15", "19"),
    ("16", "20"),
]

# Fewest tasks to a terminal state (undo counted), for every non-terminal state.
TASKS_TO_FINISH = {
    "1": 3,
    "2": 2,
    "3": 4,
    "4": 2,
    "5": 2,
    "6": 2,
    "7": 1,
    "8": 1,
    "9": 2,
    "12": 2,
    "13": 1,
    "14": 3,
    "15": 3,
    "16": 1,
    "18": 4,
    "19": 4,
}

# Table 2: (operator script, published sequence, minimum-effort sequence)
TABLE2 = [
    ("", "1 2 7 10", "1 2 7 10"),
    ("1:F1", "1 2 7 10", "1 2 7 10"),
    ("1:F2", "1 3 1 2 7 10", "1 3 1 2 7 10"),
    ("1:F3", "1 4 1 2 7 10", "1 4 8 11"),
    ("1:S12", "1 5 13 17", "1 5 13 17"),
    ("1:S23", "1 6 16 20", "1 6 16 20"),
    ("3:F02", "1 2 7 9 7 10", "1 2 7 9 7 10"),
    ("1:F3,2:S12", "1 4 8 4 1 2 7 10", "1 4 8 11"),
    ("1:S12,2:F02", "1 5 14 5 13 17", "1 5 14 5 13 17"),
]
