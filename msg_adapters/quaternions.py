"""Rotation matrices <-> unit quaternions (x, y, z, w), numerically robust at every angle up to 180 degrees."""
import numpy as np


def rotation_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (4,) unit quaternion (x, y, z, w) with w >= 0 (first non-zero of x, y, z > 0 if w == 0).

    Shepperd's method: solve for the largest of |w|, |x|, |y|, |z| first, so no division by a
    small number happens, also at 180 degrees where w = 0.
    """
    r = np.asarray(rotation, dtype=np.float64)
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    pivot = int(np.argmax([trace, r[0, 0], r[1, 1], r[2, 2]]))
    if pivot == 0:
        w = 0.5 * np.sqrt(1.0 + trace)
        q = np.array([(r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w), w])
    elif pivot == 1:
        x = 0.5 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = np.array([x, (r[0, 1] + r[1, 0]) / (4 * x), (r[0, 2] + r[2, 0]) / (4 * x), (r[2, 1] - r[1, 2]) / (4 * x)])
    elif pivot == 2:
        y = 0.5 * np.sqrt(1.0 - r[0, 0] + r[1, 1] - r[2, 2])
        q = np.array([(r[0, 1] + r[1, 0]) / (4 * y), y, (r[1, 2] + r[2, 1]) / (4 * y), (r[0, 2] - r[2, 0]) / (4 * y)])
    else:
        z = 0.5 * np.sqrt(1.0 - r[0, 0] - r[1, 1] + r[2, 2])
        q = np.array([(r[0, 2] + r[2, 0]) / (4 * z), (r[1, 2] + r[2, 1]) / (4 * z), z, (r[1, 0] - r[0, 1]) / (4 * z)])
    q /= np.linalg.norm(q)
    return canonical_sign(q)


def canonical_sign(q: np.ndarray) -> np.ndarray:
    """The one of q, -q with w > 0, or (w == 0) whose first non-zero vector component is positive."""
    leading = next((value for value in q[[3, 0, 1, 2]] if value != 0.0), 1.0)
    return q if leading > 0 else -q


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """(4,) quaternion (x, y, z, w), any non-zero norm (normalised here) -> (3, 3) rotation matrix."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
