"""LoD2 buildings from measured roof points: the JSON form, the planarity adjustment, the closed
solid, its measures and its CityJSON 2.0 form."""
