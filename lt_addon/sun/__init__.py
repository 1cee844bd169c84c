"""Sun studies (issue 58), bpy-free: the Sun's position for a place and instants (NREL SPA,
:mod:`.solar_position`) and the instants and sun directions of a study from local dates and
hours in an IANA time zone (:mod:`.study_times`)."""
