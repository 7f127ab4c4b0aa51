"""The online methods' names, importable without torch (the command line, the parameters)."""

# the methods that update the network's weights (learner.online.methods.update)
NETWORK_METHODS = ("naive", "constraint", "margin", "ewc", "replay", "rls")
# `composite`: the coefficients of a shared basis, with a memory of grounds and a
# confidence test (learner.online.composite); needs a basis model (groundfx learn basis)
METHODS = (*NETWORK_METHODS, "composite")
PROTECTING = ("constraint", "margin", "ewc", "replay")  # keep the offline weights in view
NEEDS_MEMORY = ("ewc", "replay")  # need stored offline samples
NEEDS_BASIS = ("composite",)  # need a model trained over several grounds
