"""The scaling study (``qpbench scaling``): generated arms of many links facing point clouds
(:mod:`.sizes`), their ticks benched (:mod:`.runner`), power laws fitted and reported
(:mod:`.report`)."""
