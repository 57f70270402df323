"""The simulated world: an iCub, a stand of objects, a jar of water and a floating ball (pybullet). No learning here."""

from sim.quiet import quiet_c_output

with quiet_c_output():  # pybullet prints its build time on import, from C
    import pybullet  # noqa: F401
