"""``ardrone-nmpc identify``: the drone's channels fitted from logged flights, written as a plant
profile the simulator takes (docs/identification.md)."""
