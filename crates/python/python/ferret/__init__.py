"""ferret: LLM-informed model-based object search in ProcTHOR houses, from Python.

Load or generate houses, train or load a likelihood prior, evaluate search strategies on the
same trials as ``ferret eval`` (identical costs for the same houses, strategies and seed), score
likelihood sources with :func:`calibrate`, select among strategies over an evaluation run with
:func:`select`, drive a search step by step from a robot loop with :class:`Search`, and choose
among strategies between a robot's trials with :class:`Deployment`.

The work is done by ferret's Rust crates; this package only converts arguments and results.
Long calls (``evaluate``, ``load_houses``, ``Prior.train``, building maps) release the GIL.
"""

from ._ferret import (
    DEFAULT_STRATEGIES,
    CalibrationResult,
    ConfigError,
    Container,
    Deployment,
    Evaluation,
    FerretError,
    House,
    HouseError,
    LlmError,
    Object,
    Prior,
    PriorError,
    Room,
    Search,
    SearchError,
    SelectionResult,
    StrategyError,
    __version__,
    calibrate,
    evaluate,
    generate_houses,
    load_houses,
    merge,
    select,
)

__all__ = [
    "DEFAULT_STRATEGIES",
    "CalibrationResult",
    "ConfigError",
    "Container",
    "Deployment",
    "Evaluation",
    "FerretError",
    "House",
    "HouseError",
    "LlmError",
    "Object",
    "Prior",
    "PriorError",
    "Room",
    "Search",
    "SearchError",
    "SelectionResult",
    "StrategyError",
    "__version__",
    "calibrate",
    "evaluate",
    "generate_houses",
    "load_houses",
    "merge",
    "select",
]
