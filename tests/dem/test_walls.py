"""The walls of a case, read once (fcm_fsi/dem/walls.py): the planes the blocks touch and the
planes the level set's gap fill sees are the same geometric planes."""
import numpy as np

from fcm_fsi.config.dem import DEMConfig
from fcm_fsi.config.loader import build
from fcm_fsi.dem.walls import gap_walls, wall_contact, walls_of

MAT = {"name": "m", "stiffness": 1e5, "restitution": 0.5, "friction_angle": 20.0}


def config(walls):
    return build(DEMConfig, {"dt": 1e-5, "materials": [MAT], "walls": walls,
                             "blocks": [{"shape": "sphere", "material": "m", "position": [0.5, 0.5, 0.5], "radius": 0.1}]})


WALLS = [{"kind": "plane", "material": "m", "point": [0.1, -0.2, 0.3], "normal": [1.0, 2.0, 0.0]},
         {"kind": "box", "material": "m", "lo": [-1.0, 0.0, -2.0], "hi": [1.0, 2.0, 3.0], "open_top": True},
         {"kind": "plane", "material": "m", "point": [0.0, 0.0, 1.0], "normal": [0.0, 0.0, 1.0], "remove_at": 0.5},
         {"kind": "mesh", "material": "m", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "triangles": [[0, 1, 2]]}]


def test_contact_and_gap_fill_see_the_same_planes():
    walls = walls_of(config(WALLS))
    assert len(walls.planes) == 1 + 5 + 1 and len(walls.tris) == 1          # open box: 5 faces
    np.testing.assert_array_equal(walls.until, [np.inf] * 6 + [0.5, np.inf])
    gap = walls.gap_planes(3)
    assert len(gap) == 6                                                   # the gate and the mesh left out
    n = gap[:, 3:] / np.linalg.norm(gap[:, 3:], axis=1)[:, None]
    np.testing.assert_allclose(n, walls.planes[:6, :3], rtol=0, atol=1e-15)
    # the gap plane's point lies on the contact plane n·x = d
    np.testing.assert_allclose(np.einsum("pk,pk->p", n, gap[:, :3]), walls.planes[:6, 3], rtol=0, atol=1e-15)
    # a 2D fluid sees only the planes without a z component in their normal
    assert len(gap_walls(config(WALLS), 2)) == 5
    # the box's x− face: normal +x, offset lo_x
    np.testing.assert_array_equal(walls.planes[1], [1.0, 0.0, 0.0, -1.0])


def test_no_walls_no_wall_contact():
    walls = walls_of(config([]))
    assert walls.empty and wall_contact(walls, None, 1, True) is None
    assert gap_walls(config([]), 3).shape == (0, 6)
