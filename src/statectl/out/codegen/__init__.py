"""Code generation: chart -> flat tables (:mod:`.flatten`) -> plain C++17 (:mod:`.cpp`)."""

from statectl.out.codegen.cpp import generate
from statectl.out.codegen.flat import FlatChart
from statectl.out.codegen.flatten import CODES, flatten

__all__ = ["CODES", "FlatChart", "flatten", "generate"]
