"""Pictures for the notebooks and the site, kept out of the SLAM core.

- :mod:`~helpers.viz.style`: the colours, colour map and grid every picture shares.
- :mod:`~helpers.viz.display`: where 3-D views are drawn (off-screen VTK,
  interactive only in a live JupyterLab kernel).
- :mod:`~helpers.viz.render`: point clouds with PyVista, figures as still
  images; :mod:`~helpers.viz.player`: the scan player.
- Figures by notebook: :mod:`~helpers.viz.parameter_figures` (2),
  :mod:`~helpers.viz.registration_figures` and :mod:`~helpers.viz.sweep_figures` (3),
  :mod:`~helpers.viz.submap_figures` (4), :mod:`~helpers.viz.loop_figures` and
  :mod:`~helpers.viz.loop_search` (5),
  :mod:`~helpers.viz.graph_figures` (6), :mod:`~helpers.viz.map_figures` (7),
  :mod:`~helpers.viz.ground_figures` (8);
  :mod:`~helpers.viz.plots` and :mod:`~helpers.viz.figures` gather them under
  the names the notebooks use.

Only this subpackage imports PyVista, trame and matplotlib; importing it sets
nothing (VTK's off-screen window is chosen just before PyVista is imported).
"""
