"""The parameters of a synthetic pair (:class:`SceneConfig`) and the LAS classes it writes."""

from __future__ import annotations

from dataclasses import dataclass, replace

CLASS_GROUND = 2
CLASS_VEHICLE = 6
CLASS_BOULDER = CLASS_OUTLIER = 1  # not 7: a pipeline must reject outliers itself


#: GPS errors of pairs whose files declare a vertical datum (:meth:`SceneConfig.declared_datum`):
#: (shift m, roll/pitch/yaw deg), 2-5 m and 1-3 degrees
DATUM_GPS_ERRORS = (
    ((2.4, -1.6, 0.2), (0.2, -0.3, 1.3)),
    ((-3.3, 3.1, -0.05), (-0.1, 0.1, -2.7)),
)


@dataclass(frozen=True)
class SceneConfig:
    """Parameters of a synthetic pair (lengths in metres, angles in degrees)."""

    before_size: tuple[float, float] = (158.0, 154.0)
    after_size: tuple[float, float] = (67.0, 62.7)
    before_points: int = 250_000  # "paper" scale is 2_500_000
    after_points: int = 150_000  # "paper" scale is 1_500_000
    shift_m: tuple[float, float, float] = (2.0, -1.5, 0.3)  # GPS misalignment of the after cloud
    rotation_deg: tuple[float, float, float] = (0.3, -0.2, 2.0)  # roll, pitch, yaw (after centre)
    noise_m: float = 0.03  # gaussian vertical SfM noise (each epoch)
    doming_m: float = 0.0  # amplitude of a smooth dome/bowl added to the after epoch
    vertical_bias_m: float = 0.0  # planar bias (offset + small tilt) added to the after epoch
    outlier_fraction: float = 0.0  # isolated outliers incl. floaters (class 1)
    holes: int = 0  # occlusion holes (no points) per epoch, some on change edges
    vegetation: bool = False  # bushes in both epochs, grown in the after epoch (class 3/4/5)
    objects: bool = False  # vehicles (class 6) and boulders (class 1), same place in both epochs
    relief: float = 1.0  # scale of the long waves and hills (0 = a tilted plane with local detail)
    # "piles" (3 piles ~1020 m3 + a pit ~69 m3, ~15 % of the after footprint), "none", "pit" (5 %), "pile"
    # (10 %), "excavation" (`change_fraction` of the footprint, a tall pile beside it) or a site (features.py)
    change: str = "piles"
    # "fixed": the layouts above, the same for every seed (bench/ACCURACY.md, README, demo, self-test);
    # "drawn": the seed also draws the "piles" site's works (scenes/features.py)
    works: str = "fixed"
    crs: str = "EPSG:32654"
    # a vertical CRS the files also declare (compound, e.g. "EPSG:5703"): the GPS error above remains
    vertical_datum: str | None = None
    origin: tuple[float, float, float] = (500_000.0, 3_900_000.0, 0.0)  # added to local coords
    # change="excavation": fraction of the after footprint the excavation's outline covers
    change_fraction: float = 0.4
    # --- what is not soil, and the signals a survey carries (see scenes/nuisances.py) ---
    # signals written: "class" (classification), "rgb" (colour, class 0), "lidar" (classification and
    # return numbers), "returns" (return numbers, class 0), "none" (xyz, class 0)
    signals: str = "class"
    movers: int = 0  # vehicles on the after footprint that moved between the surveys
    arrivals: int = 0  # vehicles present in the after survey only
    departures: int = 0  # vehicles present in the before survey only
    patches: int = 0  # low vegetation patches (grass) on the after footprint
    patch_change: str = "grown"  # "grown" (0.05 -> 0.2-0.6 m) or "mown" (0.3-0.6 -> 0.05 m)
    crops: bool = False  # a crop field on the after footprint (0.2 -> 0.8 m)
    slope_deg: float = 0.0  # a constant slope of the whole site (degrees, rising to the east)
    site_tone: str = "brown"  # soil colour of "rgb" scenes: "brown" or "grey"
    # --- conditions that hide or imitate earthworks (see scenes/hazards.py) ---
    water_m: float = 0.0  # standing water in the pits of the after survey (no points on it)
    equipment: int = 0  # equipment and materials that arrived (excavator, container, cabin, ...)
    meadow: float = 0.0  # share of the after footprint of a meadow mown between the surveys
    overlap: float = 1.0  # share of the after footprint's width (from the west) the before survey reaches

    @classmethod
    def paper(cls, **overrides) -> SceneConfig:
        """The paper-sized, realistic scene: 2.5 M + 1.5 M points with every nuisance on."""
        base = cls(
            before_points=2_500_000,
            after_points=1_500_000,
            shift_m=(2.5, -1.8, 0.4),
            rotation_deg=(0.3, -0.2, 2.5),
            noise_m=0.03,
            doming_m=0.03,
            outlier_fraction=0.005,
            holes=8,
            vegetation=True,
            objects=True,
        )
        return replace(base, **overrides)

    @classmethod
    def declared_datum(cls, error: int = 0, **overrides) -> SceneConfig:
        """Files that declare a vertical datum (a compound CRS: UTM 54N + NAVD88 height) yet carry
        the GPS error ``DATUM_GPS_ERRORS[error]``, on smooth terrain (relief 0.3), where the after
        survey's margin lies within 0.4 m of the before surface as surveyed although it is metres off."""
        shift, deg = DATUM_GPS_ERRORS[error]
        return replace(cls(shift_m=shift, rotation_deg=deg, relief=0.3, vertical_datum="EPSG:5703"), **overrides)

    @classmethod
    def small(cls, **overrides) -> SceneConfig:
        """Same geometry as the default, ~60 k + 40 k points, for fast tests."""
        return replace(cls(before_points=60_000, after_points=40_000), **overrides)

    def declared_crs(self):
        """The CRS the files declare (a pyproj CRS): ``crs``, compound with ``vertical_datum``."""
        import pyproj

        crs = pyproj.CRS.from_user_input(self.crs)
        if self.vertical_datum is None:
            return crs
        vertical = pyproj.CRS.from_user_input(self.vertical_datum)
        return pyproj.crs.CompoundCRS(f"{crs.name} + {vertical.name}", [crs, vertical])

    def with_total_points(self, total: int) -> SceneConfig:
        """A copy with ``total`` points split between the epochs in the current ratio."""
        frac = self.before_points / float(self.before_points + self.after_points)
        nb = int(round(total * frac))
        return replace(self, before_points=nb, after_points=int(total) - nb)
