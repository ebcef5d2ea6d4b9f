"""`hrc-drake`, the command line: every argparse handler of the project lives in this package.

`app` builds the parser and runs a command line; `tasks` holds the task layer's commands
(`states`, `solve`, `train`, `policy`, `react`, `table2`, `plot`); `evaluate`, `costs`,
`simulate` and `station` are the commands of the same names, and `scenario_args` turns
`simulate`'s and `station`'s options into a scenario. Importing the package imports no Drake:
the cell's commands load it when they run.
"""

from hrc_drake.cli.app import build_parser, main

__all__ = ["build_parser", "main"]
