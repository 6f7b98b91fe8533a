"""The model-set reader's former home: kept so that ``from estimator.modelfile import ...`` works.

Everything about model sets is in :mod:`estimator.io.modelset`.
"""

from estimator.io.modelset import (
    MODELS_DIR,
    load_model_set,
    parse_channel,
    parse_model_set,
    parse_parameter,
)

__all__ = ["MODELS_DIR", "load_model_set", "parse_channel", "parse_model_set", "parse_parameter"]
