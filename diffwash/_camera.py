"""A pinhole camera: look-at view and OpenGL perspective projection, differentiable."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = ["Camera", "look_at", "perspective"]


def _normalize(v: Array) -> Array:
    return v / jnp.linalg.norm(v)


def look_at(eye: Float[ArrayLike, "3"], target: Float[ArrayLike, "3"], up: Float[ArrayLike, "3"]) -> Float[Array, "4 4"]:
    """World-to-eye matrix (OpenGL convention: the eye looks down -z, y up).

    Callers ensure `eye != target` and `up` not parallel to the view (the scene
    loader checks it).
    """
    eye, target, up = jnp.asarray(eye), jnp.asarray(target), jnp.asarray(up)
    f = _normalize(target - eye)
    s = _normalize(jnp.cross(f, up))
    u = jnp.cross(s, f)
    rot = jnp.stack([s, u, -f])
    return jnp.concatenate(
        [jnp.concatenate([rot, -(rot @ eye)[:, None]], axis=1), jnp.array([[0.0, 0.0, 0.0, 1.0]], rot.dtype)], axis=0
    )


def perspective(
    fov_y_deg: Float[ArrayLike, ""], aspect: Float[ArrayLike, ""], near: Float[ArrayLike, ""], far: Float[ArrayLike, ""]
) -> Float[Array, "4 4"]:
    """OpenGL's perspective projection (`gluPerspective`): eye space to clip space."""
    fov_y_deg, aspect, near, far = (jnp.asarray(v) for v in (fov_y_deg, aspect, near, far))
    f = 1 / jnp.tan(jnp.radians(fov_y_deg) / 2)
    z = jnp.zeros_like(f)
    return jnp.stack(
        [
            jnp.stack([f / aspect, z, z, z]),
            jnp.stack([z, f, z, z]),
            jnp.stack([z, z, (far + near) / (near - far), 2 * far * near / (near - far)]),
            jnp.stack([z, z, -jnp.ones_like(f), z]),
        ]
    )


class Camera(eqx.Module):
    """A pinhole camera looking from `eye` at `target`.

    **Fields:** `eye`, `target`, `up` (shape (3,), world space), `fov_y` (vertical
    field of view, degrees), `near`, `far` (clip distances along the view axis).
    """

    eye: Float[ArrayLike, "3"]
    target: Float[ArrayLike, "3"]
    up: Float[ArrayLike, "3"]
    fov_y: Float[ArrayLike, ""]
    near: Float[ArrayLike, ""]
    far: Float[ArrayLike, ""]

    def view(self) -> Float[Array, "4 4"]:
        """World-to-eye matrix."""
        return look_at(self.eye, self.target, self.up)

    def projection(self, aspect: float) -> Float[Array, "4 4"]:
        """Eye-to-clip matrix for an image of `width / height = aspect`."""
        return perspective(self.fov_y, aspect, self.near, self.far)

    def view_projection(self, aspect: float) -> Float[Array, "4 4"]:
        """World-to-clip matrix."""
        return self.projection(aspect) @ self.view()
