"""The one exception the client raises for an answer the server refused."""


class NunoError(Exception):
    """The server answered `status` with `{"error": {"code", "message"}}`:
    `code` is stable (`model_not_found`, `invalid_request`, ...), `message`
    says what was wrong."""

    def __init__(self, status: int, code: str, message: str) -> None:
        super().__init__(f"{status} {code}: {message}")
        self.status = status
        self.code = code
        self.message = message
