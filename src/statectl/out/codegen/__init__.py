"""Code generation: chart -> flat tables (:mod:`.flatten`) -> plain C++17 (:mod:`.cpp`)."""

from statectl.out.codegen.cpp import generate
from statectl.out.codegen.flatten import CODES, FlatChart, flatten

__all__ = ["CODES", "FlatChart", "flatten", "generate"]
