"""Colours of the views: an instrument's colour is its place in the campaign's instruments."""

import numpy as np

from noisebo.view.style import SEED_GREY, instrument_colours

BLUE, ORANGE = (0x1F / 255, 0x77 / 255, 0xB4 / 255, 1.0), (0xFF / 255, 0x7F / 255, 0x0E / 255, 1.0)  # tab10's first two


def test_each_instrument_has_the_colour_of_its_place_in_the_config():
    colours = instrument_colours(["south", "north", "south", "west"], order=("north", "south"))
    np.testing.assert_allclose(colours, [ORANGE, BLUE, ORANGE, SEED_GREY])


def test_the_eleventh_instrument_shares_the_first_ones_colour_and_none_is_an_empty_table():
    names = [f"i{k}" for k in range(11)]
    colours = instrument_colours(["i10", "i0"], order=names)
    np.testing.assert_allclose(colours, [BLUE, BLUE])
    assert instrument_colours([], order=names).shape == (0, 4)
