"""Which benchmarks exist, and the settings of the quick and full modes."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from . import _ours


@dataclass(frozen=True)
class Bench:
    case: str
    impl: str  # a key of _peers.PEERS, or _ours.IMPL
    kind: str = "forward"  # "forward" | "value_and_grad"
    # timed grid: None = the case's full grid; (n_angles, n_wavelengths) = evenly spread subset
    grid: tuple[int, int] | None = None
    quick_grid: tuple[int, int] | None = (16, 250)
    in_quick: bool = True  # run in --quick mode too (keep --quick under 60 s)
    note: str = ""

    @property
    def key(self) -> str:
        return f"{self.case}/{self.impl}/{self.kind}"

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Mode:
    name: str
    warmup: int
    repeats: int
    min_time: float
    max_time: float  # cap on the timed phase of one benchmark (s)
    timeout: float  # kill a worker after this (s)
    agreement_grid: tuple[int, int]  # points compared with tmm (subset of the timed grid)
    grad_check_grid: tuple[int, int] | None  # gradient vs tmm finite differences (None = skip)
    validate_peers: bool = True


QUICK = Mode("quick", warmup=1, repeats=1, min_time=0.0, max_time=5.0, timeout=120.0,
             agreement_grid=(8, 25), grad_check_grid=None)
FULL = Mode("full", warmup=1, repeats=5, min_time=0.2, max_time=40.0, timeout=600.0,
            agreement_grid=(16, 100), grad_check_grid=(6, 20))

# tmm is timed on a subset and its per-point cost extrapolated to the full grid.
TMM_SUBSET = (16, 100)  # 3200 points for P1 (s and p)
TMM_QUICK_SUBSET = (8, 25)


def peer_benches() -> list[Bench]:
    return [
        Bench("P1", "tmm", "forward", grid=TMM_SUBSET, quick_grid=TMM_QUICK_SUBSET),
        Bench("P1", "tmm-fast", "forward"),
        Bench("P1", "tmm-fast", "value_and_grad"),
        Bench("P1", "tmm-faster", "forward"),
        Bench("P1", "jaxlayerlumos", "forward"),
        Bench("P1", "jaxlayerlumos", "value_and_grad", in_quick=False),  # ~10 s of eager compiles
        Bench("P1", "tmmax", "forward"),
    ]


@dataclass
class Registry:
    benches: list[Bench] = field(default_factory=list)
    hooks: dict[str, str] = field(default_factory=dict)

    def add(self, case: str, impl: str, kind: str = "forward", **kw) -> None:
        self.benches.append(Bench(case, impl, kind, **kw))


def build_registry() -> Registry:
    reg = Registry(benches=peer_benches())
    # ----------------------------------------------------------------------------------
    # >>> LAYERSTACK_JAX REGISTRATION HOOK: see benchmarks/_ours.py (API_NAMES) <<<
    # ----------------------------------------------------------------------------------
    reg.hooks[_ours.IMPL] = _ours.register(reg.add)
    return reg
