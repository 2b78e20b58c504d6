"""sphere_probe's ``probe`` block as a pydantic model, apart from ``file_face`` so that
reading a dataset of another kind (the registry imports every kind's file face) does not
import pydantic (``hostpc.dataset.schema``)."""

from __future__ import annotations

from hostpc.dataset.schema_models import StrictSchema


class ProbeSchema(StrictSchema):
    """``probe``: the stylus ball radius (length)."""

    stylus_radius: float
