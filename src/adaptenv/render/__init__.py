"""Images of houses and episodes: the top-down map people and the vision LLM (F and G) look at.

``render.topdown`` draws a house with Pillow (rooms, walls, doors, windows, furniture with ids,
the optional normalized 0..100 grid) and an episode on top of it (path yellow -> orange,
collisions, targets); ``render.labels`` decides where the id labels and room names go (an
optimiser over kinds of obstacles) and ``render.text`` measures and draws text. Nothing here is
imported by the simulator: rendering stays optional.
"""
