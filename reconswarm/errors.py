"""Errors that end a command with a documented exit code and one clear line on stderr."""

from __future__ import annotations


class ReconswarmError(Exception):
    """Base class: `exit_code` is what the command returns."""

    exit_code = 1


class BadInput(ReconswarmError):
    """Usage, scenario or configuration error (exit 2). The message names the file and the field."""

    exit_code = 2


class ProcessFailure(ReconswarmError):
    """A process of the run died or could not start (exit 3)."""

    exit_code = 3
