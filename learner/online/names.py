"""The online methods' names, importable without torch (the command line, the parameters)."""

METHODS = ("naive", "constraint", "margin", "ewc", "replay", "rls")
PROTECTING = ("constraint", "margin", "ewc", "replay")  # keep the offline weights in view
NEEDS_MEMORY = ("ewc", "replay")  # need stored offline samples
