"""Domain errors raised by services; app/api/errors.py maps each to one HTTP status and code, once."""

from __future__ import annotations


class ServiceError(Exception):
    code = "error"

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class NotFoundError(ServiceError):
    code = "not_found"


class InvalidInputError(ServiceError):
    code = "invalid_input"


class PayloadTooLargeError(ServiceError):
    code = "payload_too_large"


class QueueFullError(ServiceError):
    code = "queue_full"


class NotReadyError(ServiceError):
    """The service cannot answer yet (no vocabulary or index)."""

    code = "not_ready"


class ConflictError(ServiceError):
    code = "conflict"


class DescribeTimeoutError(ServiceError):
    code = "describe_timeout"


class DescribeCrashedError(ServiceError):
    """The process describing a query died (e.g. out of memory); the pool was restarted."""

    code = "describe_crashed"


class InsufficientStorageError(ServiceError):
    """The data directory is at its free-space floor or its quota: nothing new is written (507)."""

    code = "insufficient_storage"


class PoolBusyError(QueueFullError):
    """Every query process is busy and the wait queue is full (503 + Retry-After, as a full queue)."""

    code = "busy"


class ResourceLimitError(PayloadTooLargeError):
    """The input needs more memory (or other resources) than a pool process may use (413)."""

    code = "resource_limit"
