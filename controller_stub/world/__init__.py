"""The simulated world: the robots' own forward models and hidden physics, the controller
state every simulation shares (offsets, IO, clock), motions and guarded moves, and the
simulations that hold them. Synchronous and free of I/O."""
