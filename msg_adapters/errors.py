"""The one exception every adapter raises for bad input."""


class AdapterError(ValueError):
    """A message or array that cannot be converted; the text names the field and what was expected."""
