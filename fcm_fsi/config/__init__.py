"""Case configuration: frozen dataclasses loaded strictly from YAML."""
from .case import Case, case_from_dict, load_case
from .loader import ConfigError, to_dict

__all__ = ["Case", "ConfigError", "case_from_dict", "load_case", "to_dict"]
