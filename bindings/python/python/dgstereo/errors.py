"""The exceptions dgstereo raises; every one derives from :class:`Error`."""


class Error(Exception):
    """An error of dgstereo, carrying the library's message."""


class InputError(Error, ValueError):
    """A bad argument: an array of the wrong shape, dtype or size, a non-finite value, an
    invalid option."""


class FileError(Error, OSError):
    """A file that cannot be read, written or parsed (weights, experiment, PFM, image)."""


__all__ = ["Error", "InputError", "FileError"]
