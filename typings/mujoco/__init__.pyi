# MuJoCo's Python bindings are compiled (pybind11) and ship no type stubs, so a type checker
# cannot see their names: every attribute of the module is typed Any here.
from typing import Any

def __getattr__(name: str) -> Any: ...
