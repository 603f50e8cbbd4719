"""The scaling study (``qpbench scaling``): generated arms of many links facing point clouds
(:mod:`.arms`, :mod:`.obstacles`, :mod:`.sizes`), their ticks benched (:mod:`.runner`), power laws
fitted (:mod:`.fit`) and reported (:mod:`.report`)."""
