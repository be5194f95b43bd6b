"""Type stubs of ferret's extension module (re-exported by ``ferret``)."""

import os
from typing import Any, Callable, Dict, List, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
DEFAULT_STRATEGIES: str
"""The strategies ``evaluate`` runs when given none (comma separated)."""

_Path = Union[str, "os.PathLike[str]"]
_Protocol = Literal["ferret", "paper"]
_ContainerArg = Union[str, "Container"]
_Goal = Literal["all", "any"]
# A search's ``destination=``: "start", "container:<id>", "room:<id>", (x, y) metres, a Container.
_DestinationArg = Union[str, Tuple[float, float], "Container", None]
# A listed task of ``evaluate(tasks=[...])``: house, targets, goal and destination.
_TaskDict = Dict[str, Any]
# ``progress=``: True prints to stderr; a callable is called as ``progress(what, done, total)``.
_Progress = Union[bool, None, Callable[[str, int, int], object]]

class FerretError(Exception):
    """Base class of every error ferret raises."""

class HouseError(FerretError):
    """A house file, scene file or asset database that cannot be read, or a house that cannot
    be mapped; the message names the file, the house index and the field."""

class StrategyError(FerretError):
    """A strategy spec that names no known strategy, or a strategy that cannot be built."""

class PriorError(FerretError):
    """A prior file that cannot be read or written."""

class ConfigError(FerretError):
    """An unusable setting: a keyword argument, a protocol, grid or planner option, or the LLM
    endpoint configuration."""

class LlmError(FerretError):
    """An LLM endpoint or the LLM response cache failed."""

class SearchError(FerretError):
    """A search cannot go on: a container not in the house or already searched, or a policy
    that failed to choose."""

class Container:
    """A container: a piece of furniture the robot can search."""

    @property
    def index(self) -> int:
        """Its position in ``House.containers``."""
    @property
    def id(self) -> str:
        """Its id in the house file."""
    @property
    def type(self) -> str:
        """Its object type, e.g. ``Fridge``."""
    @property
    def room(self) -> Optional[str]:
        """The id of the room it stands in."""
    @property
    def room_type(self) -> Optional[str]:
        """The type of that room, e.g. ``Kitchen``."""
    @property
    def position(self) -> Tuple[float, float]:
        """The centre of its footprint (x, y), metres."""
    @property
    def access(self) -> Optional[Tuple[float, float]]:
        """Where the robot stands to search it (x, y), metres."""
    @property
    def house(self) -> str:
        """The name of the house it belongs to. A container is one house's: passing it to a
        ``Search`` or ``House`` method of another house raises ``SearchError``, even where the
        other house has a container with the same id."""

class Room:
    """A room."""

    @property
    def id(self) -> str:
        """Its id in the house file."""
    @property
    def type(self) -> str:
        """Its type, e.g. ``Kitchen``."""
    @property
    def polygon(self) -> List[Tuple[float, float]]:
        """Its floor polygon's vertices (x, y), metres."""

class Object:
    """A small object inside or on a container."""

    @property
    def id(self) -> str:
        """Its id in the house file."""
    @property
    def type(self) -> str:
        """Its object type, e.g. ``CellPhone``."""
    @property
    def container(self) -> str:
        """The id of the container holding it."""

class House:
    """A house: rooms, containers and what the containers hold, with its maps built on first
    use. Immutable."""

    @property
    def name(self) -> str:
        """A label naming where the house came from, e.g. ``multiroom-val150.jsonl.gz#3``."""
    @property
    def index(self) -> int:
        """The house's index in its file (or among the generated houses)."""
    @property
    def start(self) -> Tuple[float, float]:
        """The robot's start (x, y) on the floor, metres."""
    @property
    def rooms(self) -> List[Room]:
        """The rooms, in the house's order."""
    @property
    def containers(self) -> List[Container]:
        """The containers, in the house's order (row/column ``i + 1`` of ``distances()``)."""
    @property
    def objects(self) -> List[Object]:
        """Every small object and the container holding it."""
    def contents(self, container: _ContainerArg) -> List[str]:
        """The object types a container holds (its ground truth)."""
    def target_types(self) -> List[str]:
        """The object types held by some container, in name order."""
    def container_by_id(self, id: str) -> Container:
        """The container with this id."""
    def distances(
        self,
        *,
        resolution: float = 0.05,
        robot_radius: float = 0.18,
        wall_thickness: float = 0.05,
        protocol: _Protocol = "ferret",
    ) -> npt.NDArray[np.float64]:
        """Shortest travel distances, metres, ``(n + 1) × (n + 1)``: index 0 is the robot's
        start, ``i + 1`` container ``i``."""

class Prior:
    """A likelihood prior: P(container holds target | container type, room type)."""

    @staticmethod
    def train(
        houses: Sequence[House],
        smoothing: float = 2.0,
        embeddings: Optional[_Path] = None,
        learned_folds: int = 5,
        learned_seed: int = 0,
    ) -> "Prior":
        """Learns a prior from training houses, as ``ferret prior train``; with ``embeddings``
        (a folder, as ``--embeddings``) also the learned likelihood of ``model/learned``."""
    @staticmethod
    def load(path: _Path) -> "Prior":
        """Reads a prior written by ``Prior.save`` or ``ferret prior train``."""
    @staticmethod
    def default() -> "Prior":
        """The prior ``ferret eval`` uses when given none."""
    def save(self, path: _Path) -> None:
        """Writes the prior as JSON."""
    def probability(self, target: str, container: str, room: Optional[str] = None) -> float:
        """P(a container of type ``container`` in a room of type ``room`` holds ``target`` | the
        target is in the house), calibrated: what ``model/prior`` plans with."""
    @property
    def houses(self) -> int:
        """Number of training houses."""
    @property
    def containers(self) -> int:
        """Number of training containers."""
    @property
    def smoothing(self) -> float:
        """The smoothing weight it was trained with."""
    @property
    def learned(self) -> Optional[str]:
        """The embeddings of its learned likelihood (e.g. ``glove-6b-50d``), or None."""

class Search:
    """One trial in progress, driven step by step by a robot loop: one target, or a household
    task (1 to 4 targets, every one or any one, optionally brought to a destination)."""

    def __init__(
        self,
        house: House,
        target: Union[str, Sequence[str]],
        strategy: str = "model/prior",
        *,
        goal: _Goal = "all",
        destination: _DestinationArg = None,
        prior: Union[Prior, _Path, None] = None,
        config: Optional[_Path] = None,
        llm_cache: Optional[_Path] = None,
        offline: bool = False,
        fusion: Optional[_Path] = None,
        max_containers: int = 8,
        exact_max: int = 16,
        search_cost: float = 0.0,
        resolution: float = 0.05,
        robot_radius: float = 0.18,
        wall_thickness: float = 0.05,
        protocol: _Protocol = "ferret",
    ) -> None:
        """Starts a search for ``target`` (an object type, or a list of 1 to 4 distinct ones
        wanted ``goal="all"`` or ``"any"``) in ``house`` with the strategy spec ``strategy``,
        bringing what it finds to ``destination`` (None, ``"start"``, ``"container:<id>"``,
        ``"room:<id>"``, an ``(x, y)`` point in metres, or a Container of the house).

        Raises ConfigError for a target no container of the house holds, naming the type most
        likely meant (``"wallet"``: did you mean ``"Wallet"``?), a target given twice, more
        than 4, an unknown goal, or a destination the house does not have or the robot cannot
        reach."""
    def next_container(
        self, leaving: Optional[Sequence[_ContainerArg]] = None
    ) -> Optional[Container]:
        """The container to search next, or None once found (the goal holds), everything was
        searched, or the search was finished. In a team, ``leaving`` lists the containers
        teammates are heading to: never proposed (None when only those are left)."""
    def observe(
        self,
        container: _ContainerArg,
        found: bool = False,
        objects: Optional[Sequence[str]] = None,
        found_targets: Optional[Sequence[str]] = None,
    ) -> None:
        """Records what a teammate saw in ``container`` (arguments as ``record``): known at
        once, without this robot moving."""
    def record(
        self,
        container: _ContainerArg,
        found: bool = False,
        objects: Optional[Sequence[str]] = None,
        found_targets: Optional[Sequence[str]] = None,
    ) -> float:
        """Records a searched container and what it held; returns the leg's length, metres.

        One target: ``found`` says it was there. Several: the targets found are those in
        ``found_targets`` or ``objects``; ``found=True`` naming none raises ConfigError."""
    def finish(self) -> float:
        """Goes to the destination: returns the last leg, metres (0 without one), then part of
        ``cost``; calling it again adds nothing."""
    def distance_to(self, container: _ContainerArg) -> float:
        """Travel distance from where the robot is to ``container``, metres."""
    def path_to(self, container: _ContainerArg) -> List[Tuple[float, float]]:
        """The shortest grid path from where the robot is to ``container``, (x, y) metres."""
    def path_to_destination(self) -> Optional[List[Tuple[float, float]]]:
        """The grid path from where the robot is to the destination, (x, y) metres; None
        without a destination."""
    @property
    def cost(self) -> float:
        """Metres travelled so far (with the way to the destination once finished)."""
    @property
    def searched(self) -> List[str]:
        """Ids of the containers searched, in order."""
    @property
    def found(self) -> Optional[Container]:
        """The container where the target was found (where a task's goal came to hold), or
        None."""
    @property
    def found_in(self) -> Dict[str, Container]:
        """Each target found so far and the container it was first seen in, in task order."""
    @property
    def goal_holds(self) -> bool:
        """True once every target (``all``) or one (``any``) was found."""
    @property
    def done(self) -> bool:
        """True once the target was found (the goal holds), every container was searched, or
        the search was finished."""
    @property
    def target(self) -> str:
        """The object type searched for; a task's targets joined by ``+`` (all) or ``|`` (any)."""
    @property
    def targets(self) -> List[str]:
        """The target types, in the task's order."""
    @property
    def goal(self) -> _Goal:
        """``"all"`` or ``"any"``."""
    @property
    def destination(self) -> Optional[Tuple[float, float]]:
        """Where the robot brings what it found, (x, y) metres, or None."""
    @property
    def strategy(self) -> str:
        """The strategy's spec."""
    @property
    def house(self) -> House:
        """The house searched."""
    def likelihoods(self, target: Optional[str] = None) -> Optional[List[float]]:
        """The strategy's probability for each container (house order) that ``target`` (one
        of the search's targets, default the first) is there, or None without a source."""

class Deployment:
    """A live deployment: chooses each trial's strategy and learns from the robot's searches."""

    def __init__(
        self,
        strategies: Sequence[str],
        *,
        method: str = "replay",
        c: float = 5.0,
        seed: int = 0,
        prior: Union[Prior, _Path, None] = None,
        config: Optional[_Path] = None,
        llm_cache: Optional[_Path] = None,
        offline: bool = False,
        fusion: Optional[_Path] = None,
        max_containers: int = 8,
        exact_max: int = 16,
        search_cost: float = 0.0,
        protocol: _Protocol = "ferret",
    ) -> None:
        """A deployment over ``strategies`` (at least two), as ``ferret deploy`` runs it."""
    def choose(self) -> str:
        """The strategy spec of the trial in progress (chosen now if none is)."""
    def finish(self, search: Search) -> Dict[str, float]:
        """Ends the trial with a search that found its target (whose task's goal holds; a
        destination not yet reached is reached first); every candidate's cost on it, each
        replayed on the same task."""
    def abandon(self) -> None:
        """Ends the trial in progress without a cost (the target was nowhere)."""
    @property
    def strategies(self) -> List[str]:
        """The candidate strategies, in order."""
    @property
    def trials(self) -> int:
        """Trials ended so far."""
    def stats(self) -> List[Dict[str, Any]]:
        """Per candidate: deployed, mean_cost_m, replay_mean_m, score."""

class Evaluation:
    """The result of ``evaluate``: rows with the columns of ``trials.csv``."""

    @property
    def rows(self) -> List[Dict[str, Any]]:
        """One dict per trial and strategy, with ``trials.csv``'s columns."""
    @property
    def columns(self) -> List[str]:
        """The rows' column names, in order."""
    @property
    def errors(self) -> List[str]:
        """One message per house or trial that failed."""
    @property
    def houses_run(self) -> int:
        """Houses with a map and a target."""
    @property
    def trials_run(self) -> int:
        """Trials (house and target) drawn on those houses."""
    @property
    def strategies(self) -> List[str]:
        """The strategies evaluated, in order."""
    def summary(self) -> List[Dict[str, Any]]:
        """Per strategy, the rows of ``summary.csv``."""
    def to_pandas(self) -> Any:
        """The rows as a ``pandas.DataFrame`` (needs pandas)."""
    def save(self, dir: _Path, *, paired_against: Union[str, Sequence[str], None] = None) -> None:
        """Writes the files ``ferret eval`` writes into ``dir``: ``trials.csv``, ``summary.csv``,
        ``paired.csv`` (every strategy against the best, and against each of
        ``paired_against``; a shard writes none, ``merge`` compares over all shards),
        ``summary.md`` and ``run.json`` (with the shard, for ``merge``)."""
    def __len__(self) -> int: ...

class CalibrationResult:
    """The result of ``calibrate``: one row per source with ``calibration.csv``'s columns."""

    @property
    def rows(self) -> List[Dict[str, Any]]:
        """One dict per scored source, with ``calibration.csv``'s columns."""
    @property
    def reliability(self) -> Dict[str, List[Dict[str, float]]]:
        """Per source, its reliability bins.

        Each bin: ``lo``, ``hi``, ``count``, ``mean_p``, ``observed``.
        """
    @property
    def trials(self) -> int:
        """(house, target) pairs scored."""
    @property
    def markdown(self) -> str:
        """The table of scores as Markdown (``calibration.md``)."""
    @property
    def fusion(self) -> Optional[str]:
        """The fitted fusion weights as JSON (for ``fusion=``), or ``None``."""
    @property
    def fusion_markdown(self) -> Optional[str]:
        """The fitted fusions as Markdown, or ``None``."""
    @property
    def errors(self) -> List[str]:
        """One message per source or trial that failed."""
    def to_pandas(self) -> Any:
        """The rows as a ``pandas.DataFrame`` (needs pandas)."""
    def __len__(self) -> int: ...

class SelectionResult:
    """The result of ``select``: curves against the trial count k per selection method."""

    @property
    def strategies(self) -> List[str]:
        """The candidate strategies, in the run's order."""
    @property
    def best_strategy(self) -> str:
        """The strategy with the lowest mean cost over the run's houses."""
    @property
    def mean_costs(self) -> Dict[str, float]:
        """Each candidate's mean cost over the run's houses, metres."""
    @property
    def methods(self) -> List[str]:
        """The selection methods that ran (``ucb``, ``replay``)."""
    @property
    def curves(self) -> Dict[str, Dict[str, List[float]]]:
        """Per method: ``avg_cost``, ``cum_regret``, ``paper_regret`` against k.

        ``best``: ``avg_cost``.
        """
    @property
    def rows(self) -> List[Dict[str, Any]]:
        """The rows of ``selection.csv``."""
    @property
    def choices(self) -> List[Dict[str, Any]]:
        """The rows of ``choices.csv``."""
    @property
    def markdown(self) -> str:
        """The tables of ``selection.md``."""
    @property
    def deployments(self) -> int:
        """Deployments run."""
    @property
    def trials_per_deployment(self) -> int:
        """Trials per deployment."""
    def to_pandas(self) -> Any:
        """The rows of ``selection.csv`` as a ``pandas.DataFrame`` (needs pandas)."""

def load_houses(
    path: _Path,
    *,
    asset_db: Optional[_Path] = None,
    range: Union[str, "range", None] = None,
    skip_invalid: bool = False,
    containers: Literal["receptacles", "furniture"] = "receptacles",
) -> List[House]:
    """Loads ProcTHOR houses (.json, .jsonl, .jsonl.gz) or a ferret scene file."""

def generate_houses(n: int, seed: int = 0) -> List[House]:
    """Generates ``n`` houses from ``seed`` (``ferret eval --generate n --house-seed seed``)."""

def evaluate(
    houses: Sequence[House],
    strategies: Union[Sequence[str], str, None] = None,
    *,
    prior: Union[Prior, _Path, None] = None,
    seed: int = 0,
    trials_per_house: Union[int, Literal["all"], None] = None,
    reveal_fraction: float = 0.0,
    task: Optional[str] = None,
    deliver: Optional[str] = None,
    tasks: Union[_Path, Sequence[_TaskDict], None] = None,
    protocol: _Protocol = "ferret",
    cells: bool = False,
    max_containers: int = 8,
    exact_max: int = 16,
    search_cost: float = 0.0,
    config: Optional[_Path] = None,
    llm_cache: Optional[_Path] = None,
    offline: bool = False,
    keep_going: bool = False,
    fusion: Optional[_Path] = None,
    resolution: float = 0.05,
    robot_radius: float = 0.18,
    wall_thickness: float = 0.05,
    progress: _Progress = None,
    shard: Optional[Tuple[int, int]] = None,
    robots: Optional[int] = None,
    starts: Literal["together", "spread"] = "together",
) -> Evaluation:
    """Evaluates strategies on houses as ``ferret eval`` does (identical costs); with
    ``shard=(i, n)`` only the houses whose file index is i modulo n. ``task="all:3"`` (or
    ``"any:2"``) draws household tasks per house, brought to ``deliver`` (``"start"``,
    ``"room:<RoomType>"``, ``"container:<ObjectType>"``); ``tasks`` lists them (a tasks file's
    path, or dicts with ``house``, ``targets``, ``goal``, ``destination``). ``robots=N`` runs
    every trial with a team of N robots (``starts="together"`` or ``"spread"``), as ``ferret
    eval --robots`` does: ``cost_m`` is the makespan."""

def merge(
    runs: Sequence[_Path],
    out: _Path,
    *,
    caches: Optional[Sequence[_Path]] = None,
    cache_out: Optional[_Path] = None,
) -> Dict[str, Any]:
    """Merges shards' run directories (and LLM caches) into the run one machine writes."""

def calibrate(
    houses: Sequence[House],
    sources: Union[Sequence[str], str, None] = None,
    *,
    targets_per_house: Union[int, Literal["all"], None] = None,
    seed: int = 0,
    bins: int = 10,
    fit_fusion: bool = False,
    prior: Union[Prior, _Path, None] = None,
    max_containers: int = 8,
    exact_max: int = 16,
    search_cost: float = 0.0,
    config: Optional[_Path] = None,
    llm_cache: Optional[_Path] = None,
    offline: bool = False,
    keep_going: bool = False,
    fusion: Optional[_Path] = None,
    progress: _Progress = None,
) -> CalibrationResult:
    """Scores likelihood sources against the houses' ground truth as ``ferret calibrate`` does."""

def select(
    trials: _Path,
    *,
    deployments: int = 500,
    trials_per_deployment: int = 100,
    c: float = 5.0,
    seed: int = 0,
    replay_untried_first: bool = False,
    replay: Optional[Literal["pessimistic", "counterfactual"]] = None,
    draw: Optional[Literal["distinct", "replacement"]] = None,
    config: Optional[_Path] = None,
    llm_cache: Optional[_Path] = None,
    offline: bool = False,
    keep_going: bool = False,
    fusion: Optional[_Path] = None,
    progress: _Progress = None,
) -> SelectionResult:
    """UCB and replay selection over an evaluation run, as ``ferret select --trials`` does."""
