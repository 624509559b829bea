"""Errors of the twin layer, and the set of errors the CLI reports as one clear line."""
from fea import FEAInputError
from meshes.tomlspec import DefinitionError


class TwinInputError(ValueError):
    """Bad input to a twin workflow (dataset, channel, option); the message names it and the value."""


#: Everything that means "the user gave something wrong", not "the program is broken".
USER_ERRORS = (TwinInputError, DefinitionError, FEAInputError)
