"""What the checks share."""

from __future__ import annotations

from ..errors import ValidationError


def expect_validation_error(call, description: str) -> None:
    """Assert that `call()` raises flockkit.errors.ValidationError; `description` names the call."""
    try:
        call()
    except ValidationError:
        return
    except Exception as exc:  # noqa: BLE001 - the wrong error type is the failure we report
        raise AssertionError(f"{description} raised {type(exc).__name__}, not ValidationError") from exc
    raise AssertionError(f"{description} raised nothing; expected ValidationError")
