"""Errors of the twin layer, and the set of errors the CLI reports as one clear line."""
import sys


class TwinInputError(ValueError):
    """Bad input to a twin workflow (dataset, channel, option); the message names it and the value."""


#: Error classes of the lower layers that mean "the user gave something wrong", as (module, class name).
_LOWER_LAYER_ERRORS = (("fea.errors", "FEAInputError"), ("meshes.tomlspec", "DefinitionError"))


def user_errors() -> tuple[type[Exception], ...]:
    """Everything that means "the user gave something wrong", not "the program is broken".

    Looked up in ``sys.modules`` rather than imported: importing ``fea`` pulls in
    scipy (seconds of start-up), and an error class whose module was never
    loaded cannot have been raised.

    Returns
    -------
    tuple of type
        :class:`TwinInputError` and the loaded lower layers' input errors.
    """
    found = [TwinInputError]
    for module, name in _LOWER_LAYER_ERRORS:
        if module in sys.modules:
            found.append(getattr(sys.modules[module], name))
    return tuple(found)
