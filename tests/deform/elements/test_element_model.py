"""The interface mass-spring and ChainMail share (voxwarp.deform.elements.model)."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.deform import ChainMail, ElementGrid, ElementModel, MassSpring
from voxwarp.deform.elements.chainmail_model import ChainMailError
from voxwarp.deform.elements.massspring import MassSpringError

BOX = ((0.0, 0.0, 0.0), (30.0, 20.0, 10.0))


@pytest.mark.parametrize("cls", [MassSpring, ChainMail])
def test_models_are_element_models_and_resume_from_their_warp(cls: type) -> None:
    model = cls(ElementGrid(BOX, shape=(4, 4, 3), anchor="corners"))
    assert isinstance(model, ElementModel)
    model.move((2, 2, 1), (3.0, 0.0, 0.0))
    if isinstance(model, MassSpring):
        model.settle()
    warp = model.warp()
    again = cls.from_warp(type(warp).from_dict(warp.to_dict()))
    np.testing.assert_allclose(again.displacements(), model.displacements(), atol=1e-9)
    model.close()
    model.close()  # idempotent
    again.close()


@pytest.mark.parametrize(
    ("cls", "error"), [(MassSpring, MassSpringError), (ChainMail, ChainMailError)]
)
def test_from_warp_names_the_model_it_needs(cls: type, error: type) -> None:
    other = ChainMail if cls is MassSpring else MassSpring
    warp = other(ElementGrid(BOX, shape=3, anchor="corners")).warp()
    with pytest.raises(error, match=f"only warps saved from a {cls.__name__} can be resumed"):
        cls.from_warp(warp)
