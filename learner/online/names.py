"""The online methods' names, importable without torch (the command line, the parameters).
Every other list of methods reads this one."""

# the methods that update the network's weights (learner.online.methods.update)
NETWORK_METHODS = ("naive", "constraint", "margin", "ewc", "replay", "rls")
# `composite`: the coefficients of a shared basis, with a memory of grounds and a
# confidence test (learner.online.composite); needs a basis model (groundfx learn basis)
METHODS = (*NETWORK_METHODS, "composite")
PROTECTING = ("constraint", "margin", "ewc", "replay")  # keep the offline weights in view
NEEDS_MEMORY = ("ewc", "replay")  # need stored offline samples
NEEDS_BASIS = ("composite",)  # need a model trained over several grounds

OFF = "off"
# the values of the MAVLink parameter GFX_OL_METHOD: 0 learns nothing, k the k-th method
METHOD_NUMBERS = (OFF, *METHODS)


def method_number(method: str | None) -> int:
    """GFX_OL_METHOD's value for `method` (None: off)."""
    return METHOD_NUMBERS.index(method or OFF)


def method_of_number(number: int) -> str | None:
    """The method GFX_OL_METHOD = `number` asks for; None when learning is off."""
    method = METHOD_NUMBERS[number]
    return None if method == OFF else method


def method_number_doc() -> str:
    """GFX_OL_METHOD's values as a ground station's parameter description lists them."""
    return ", ".join(f"{i} {m}" for i, m in enumerate(METHOD_NUMBERS))
