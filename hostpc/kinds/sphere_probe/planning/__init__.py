"""sphere_probe's pure planning: the probe setup (``setup``), the contacts on the sphere
(``contacts``) and the sphere geometry's starting values (``geometry``)."""
