"""The procedural house generator's config: every number of the generator in one frozen dataclass."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class HouseConfig:
    """Every number of the generator (metres, probabilities, counts); frozen so it can key caches."""

    # layout
    min_rooms: int = 4
    max_rooms: int = 12
    room_area: tuple[float, float] = (11.0, 20.0)  # mean m^2 per room when sizing the footprint
    aspect: tuple[float, float] = (1.0, 1.6)
    min_room_side: float = 2.5
    max_room_side: float = 7.0
    split_fraction: tuple[float, float] = (0.3, 0.7)
    hallway_prob: float = 0.6
    hallway_min_rooms: int = 5
    hallway_width: tuple[float, float] = (1.3, 1.9)
    hallway_max_length: float = 9.0
    hallway_max_short_side: float = 3.0  # a non-strip room may be called a hallway only when this narrow
    closet_max_area: float = 8.0
    bathroom_max_area: float = 12.0  # larger rooms are rarely bathrooms
    garage_min_area: float = 16.0
    room_weights: tuple[tuple[str, float], ...] = (
        ("bedroom", 3.0), ("bathroom", 2.2), ("dining room", 1.2), ("office", 1.0), ("laundry room", 0.6),
        ("closet", 0.5), ("entryway", 0.4), ("playroom", 0.4), ("gym", 0.3), ("garage", 0.4),
        ("hallway", 0.2),
    )  # fmt: skip
    upper_room_weights: tuple[tuple[str, float], ...] = (
        ("bedroom", 4.0), ("bathroom", 2.5), ("office", 1.0), ("closet", 0.6), ("playroom", 0.5),
        ("laundry room", 0.4), ("gym", 0.3), ("hallway", 0.2),
    )  # fmt: skip
    repeatable_rooms: tuple[str, ...] = ("bedroom", "bathroom", "hallway", "closet")
    private_ground_min_rooms: int = 6  # with an upper storey, the ground floor still gets a bed/bath from here
    layout_attempts: int = 50
    # structure
    wall_thickness: float = 0.1
    wall_height: float = 2.6
    door_width: tuple[float, float] = (0.9, 1.1)
    door_height: float = 2.1
    door_corner_margin: float = 0.25  # door edge to wall corner
    extra_door_prob: float = 0.3
    second_floor_prob: float = 0.3
    min_upper_rooms: int = 2
    min_rooms_two_floors: int = 6  # total rooms needed before a house may get an upper storey
    floor_to_floor: float = 3.0
    slab_thickness: float = 0.12
    ceiling_thickness: float = 0.1
    # furnishing
    floor_density: float = 0.4  # floor objects per m^2 of room interior
    max_floor_per_room: int = 10
    max_same_category: int = 2
    wall_objects: tuple[int, int] = (1, 4)
    ceiling_prob: float = 0.8
    surface_fill: float = 4.0  # surface objects per m^2 of support top
    max_per_surface: int = 4
    surface_prob: float = 0.8
    max_objects: int = 260
    door_clear_depth: float = 1.0  # free zone in front of a doorway, both sides
    door_clear_margin: float = 0.2  # added to each side of the door width
    nav_radii: tuple[float, ...] = (0.17, 0.22)  # clearances at which each room's free space stays one piece
    min_gap: float = 0.5  # obstacles either touch (<= snap_gap) or leave at least this much space between
    snap_gap: float = 0.01
    grid_res: float = 0.05
    overlap_tol: float = 0.005
    placement_attempts: int = 24
    against_wall_prob: float = 0.75
    corner_snap_prob: float = 0.35
    free_yaw_prob: float = 0.25  # free-standing objects at an arbitrary yaw
    wall_center_height: tuple[float, float] = (1.2, 1.8)
    wall_corner_margin: float = 0.1
    agent_height: float = 1.41
    max_climb: float = 0.1
    head_margin: float = 0.15  # ceiling objects stay this far above the agent's head
    # appearance
    color_jitter: float = 0.1
    canonical_label_prob: float = 0.5  # else one of the category's other raw labels
    bake_shading: bool = False  # darken faces by orientation (off: the renderers shade by normal already)
    cylinder_segments: int = 12
    # "category": every category is dressed in its own look (looks.py: siblings of a shape family differ,
    # synonyms match); "family": the looks before issue 37 (siblings differ only in colour and size)
    looks: str = "category"
