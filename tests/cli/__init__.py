"""The command line, its fuzzing, the README's commands, figures and the package layout."""
