"""A user module that raises a BaseException on import (for tests/hostile/impl_base_exception.yaml)."""


class Doom(BaseException):
    pass


raise Doom("not an Exception")
