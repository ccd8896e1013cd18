"""Parameters fitted to the flight: the reference's values on the reference's
flight, the footprint's lengths on another one, and what the user set kept."""

import dataclasses

import pytest

from helpers.config.tables import Config
from helpers.slam.flight_fit import DESCRIPTOR_GRID_FACTOR, REFERENCE_HEIGHT, Flight, fit_to_flight, flight_of


def test_the_reference_flight_gets_the_reference_values_but_a_coarser_descriptor_grid(default_dataset):
    flight = flight_of(default_dataset)
    assert flight.height == pytest.approx(REFERENCE_HEIGHT, abs=1.0) and flight.spacing == pytest.approx(2.0)
    fitted, reasons = fit_to_flight(flight, Config())
    assert fitted.features.grid_step == DESCRIPTOR_GRID_FACTOR * Config().features.grid_step == 3.0
    assert fitted == Config().with_values(features={"grid_step": 3.0})  # ICP, the map and distances: the reference's
    assert len(reasons) == 8 and all(line.startswith("[") for line in reasons)


def test_the_descriptor_grid_doubles_only_above_the_surface_floor():
    """250 m up (k = 0.41) the footprint's step would be 0.62 m and is held at the 1 m surface, which ICP, the map
    and the distances follow; the descriptors' doubled step, 1.24 m, lies above the floor and is kept."""
    middle = Flight(height=250.0, spacing=2.0, surface_cell=1.0, strip=22.0)
    fitted, _ = fit_to_flight(middle, Config())
    assert fitted.features.grid_step == 1.25
    assert fitted.registration.icp_grid_step == 0.5 and fitted.map.align_grid_step == 0.8
    assert fitted.registration.inlier_distance == 2.0 and fitted.registration.max_distance == pytest.approx(0.67)


def test_a_low_flight_gets_the_footprint_lengths():
    """A quarter of the height: the strip is a quarter as long, so every scan is
    accepted; the grid cannot be finer than the 1 m surface; a loop lies a quarter
    as far back, in submaps of 3 scans 2 m apart."""
    low = Flight(height=REFERENCE_HEIGHT / 4, spacing=2.0, surface_cell=1.0, strip=13.2)
    fitted, reasons = fit_to_flight(low, Config())
    assert fitted.registration.skip_frames == 1
    assert fitted.features.grid_step == 1.0  # 0.375 m by the height, held at the surface's 1 m
    assert fitted.registration.icp_grid_step == 0.5 and fitted.map.align_grid_step == 0.8
    assert fitted.registration.max_distance == pytest.approx(2 / 3, abs=0.01)
    assert fitted.registration.inlier_distance == 2.0
    assert fitted.loop_closure.sub_map_thresh == round(270 / 4 / (3 * 1 * 2.0))  # 67.5 m back: 11 submaps
    assert any("a loop candidate lies 66 m of flight back" in line for line in reasons)
    assert fitted.loop_closure.rmse_threshold == 0.15  # a quarter of the reference's 0.6 m: the rows are 4 x closer
    # every scan accepted: ICP onto the last six scans merged, and no edges back (the map holds their scans)
    assert fitted.registration.icp_local_map == 6 and fitted.pose_graph.edges_back == 1
    # ... and every edge weighed by its own registration's information, loops under Huber's kernel, the motion
    # factor on
    assert (fitted.pose_graph.graph_weights, fitted.pose_graph.loop_kernel) == ("hessian", "huber")
    assert fitted.pose_graph.motion_factor
    # ... ICP given time to slide home along the track, and each step's information from the plane Hessian,
    # which sees a step over flat ground loose along it
    assert fitted.registration.icp_max_iterations == 100 and fitted.pose_graph.information == "plane"
    assert len(reasons) == 15
    # the rest is the reference's
    untouched = ("neighbors", "match_threshold", "match_ratio")
    assert all(getattr(fitted.features, k) == getattr(Config().features, k) for k in untouched)
    assert fitted.loop_closure.loop_closure_search_radius == Config().loop_closure.loop_closure_search_radius


def test_a_high_flight_with_sparse_waypoints():
    high = Flight(height=2 * REFERENCE_HEIGHT, spacing=4.0, surface_cell=1.0, strip=105.0)
    fitted, _ = fit_to_flight(high, Config())
    assert fitted.registration.skip_frames == 3  # twice the strip, waypoints twice as far apart
    assert fitted.features.grid_step == 6.0  # twice the footprint's 3 m step, which the distances follow
    assert fitted.registration.icp_grid_step == 1.5 and fitted.registration.inlier_distance == 6.0
    assert fitted.loop_closure.sub_map_thresh == 15  # 540 m back, 36 m of flight per submap
    assert fitted.registration.icp_local_map == 1 and fitted.pose_graph.edges_back == Config().pose_graph.edges_back
    assert (fitted.pose_graph.graph_weights, fitted.pose_graph.loop_kernel) == ("icp", "cauchy")  # our defaults
    assert not fitted.pose_graph.motion_factor
    assert fitted.loop_closure.rmse_threshold == 1.2  # rows twice as far apart: a true match scores twice as much


def test_the_loop_threshold_never_drops_below_the_range_noise():
    """40 m above the ground the height would give 0.04 m; two scans of one plane already differ by their range
    noise, so the threshold stays at 4 of its sigmas, and follows a noisier sensor."""
    very_low = Flight(height=40.0, spacing=2.0, surface_cell=1.0, strip=3.5)
    assert fit_to_flight(very_low, Config())[0].loop_closure.rmse_threshold == 0.08
    noisy = Config().with_values(sensor={"range_noise": 0.05})
    assert fit_to_flight(very_low, noisy)[0].loop_closure.rmse_threshold == 0.2


def test_what_the_user_set_is_kept():
    low = Flight(height=REFERENCE_HEIGHT / 4, spacing=2.0, surface_cell=1.0, strip=13.2)
    mine = Config().with_values(features=dict(grid_step=0.8))
    fitted, reasons = fit_to_flight(low, mine, keep={("features", "grid_step")})
    assert fitted.features.grid_step == 0.8 and fitted.registration.skip_frames == 1
    assert "[features] grid_step = 0.8: as given" in reasons
    assert dataclasses.replace(fitted, features=mine.features).features == mine.features


def test_a_low_flight_keeps_the_weights_the_user_set():
    """The information weights a low flight gets are a fitted value like the others: a config file that sets the
    graph's weights, its kernel or the motion factor keeps them (as the reference's identity weights, one config
    away)."""
    low = Flight(height=REFERENCE_HEIGHT / 4, spacing=2.0, surface_cell=1.0, strip=13.2)
    mine = Config().with_values(pose_graph=dict(graph_weights="identity", loop_kernel="none", motion_factor=False))
    keep = {("pose_graph", "graph_weights"), ("pose_graph", "loop_kernel"), ("pose_graph", "motion_factor")}
    fitted, reasons = fit_to_flight(low, mine, keep=keep)
    assert (fitted.pose_graph.graph_weights, fitted.pose_graph.loop_kernel) == ("identity", "none")
    assert not fitted.pose_graph.motion_factor
    assert "[pose_graph] graph_weights = 'identity': as given" in reasons
    assert fitted.registration.icp_local_map == 6  # the rest is still fitted


def test_a_low_flight_registered_scan_to_scan_keeps_the_fixed_sigmas():
    """The information weights were measured on the graph the fit builds (a local map, no edges back). A config
    file that asks for scan-to-scan steps with edges back, which measure the same ground again, keeps our fixed
    sigmas and Cauchy's kernel: under each edge's information that ground would count several times over."""
    low = Flight(height=REFERENCE_HEIGHT / 4, spacing=2.0, surface_cell=1.0, strip=13.2)
    mine = Config().with_values(registration=dict(icp_local_map=1), pose_graph=dict(edges_back=4))
    for keep in ({("registration", "icp_local_map"), ("pose_graph", "edges_back")}, {("pose_graph", "edges_back")}):
        fitted, _ = fit_to_flight(low, mine, keep=keep)
        assert (fitted.pose_graph.graph_weights, fitted.pose_graph.loop_kernel) == ("icp", "cauchy")
        assert not fitted.pose_graph.motion_factor
    # a local map of the user's own size, without edges back, is still the fit's graph
    mine = Config().with_values(registration=dict(icp_local_map=4))
    fitted, _ = fit_to_flight(low, mine, keep={("registration", "icp_local_map")})
    assert fitted.pose_graph.graph_weights == "hessian" and fitted.registration.icp_local_map == 4


def test_a_run_with_gnss_weighs_its_edges_by_their_information(default_dataset):
    """Against absolute fixes the edges' sigmas count at their size, so a run with GNSS weighs each edge by its
    registration's information where scans are skipped; a low flight keeps the low flights' rule (scan to scan
    with edges back, the fixed sigmas), and weights the user set are kept."""
    flight = flight_of(default_dataset)
    fitted, reasons = fit_to_flight(flight, Config(), gnss=True)
    assert fitted == Config().with_values(features={"grid_step": 3.0}, pose_graph={"graph_weights": "hessian"})
    assert any(line.startswith("[pose_graph] graph_weights = 'hessian': GNSS") for line in reasons)
    assert fit_to_flight(flight, Config())[0].pose_graph.graph_weights == "icp"  # lidar alone: unchanged
    mine = Config().with_values(pose_graph={"graph_weights": "identity"})
    kept, _ = fit_to_flight(flight, mine, keep={("pose_graph", "graph_weights")}, gnss=True)
    assert kept.pose_graph.graph_weights == "identity"
    low = Flight(height=REFERENCE_HEIGHT / 4, spacing=2.0, surface_cell=1.0, strip=13.2)
    scan_to_scan = Config().with_values(registration=dict(icp_local_map=1), pose_graph=dict(edges_back=4))
    keep = {("registration", "icp_local_map"), ("pose_graph", "edges_back")}
    assert fit_to_flight(low, scan_to_scan, keep=keep, gnss=True)[0].pose_graph.graph_weights == "icp"
    assert fit_to_flight(low, Config(), gnss=True) == fit_to_flight(low, Config())


def test_a_simulated_risley_flight_gives_the_motion_factor_its_own_speed():
    """A Risley flight is simulated on a clock ([sensor] speed): the motion factor, which turns a step into
    its time by the drone's speed, gets that speed, unless the user set one; a fan flight keeps the default."""
    flight = Flight(height=100.0, spacing=2.0, surface_cell=1.0, strip=20.0)
    risley = Config().with_values(sensor={"pattern": "risley", "speed": 6.0})
    fitted, reasons = fit_to_flight(flight, risley)
    assert fitted.pose_graph.motion_speed == 6.0 and any("motion_speed = 6.0" in r for r in reasons)
    kept, _ = fit_to_flight(flight, risley, keep={("pose_graph", "motion_speed")})
    assert kept.pose_graph.motion_speed == Config().pose_graph.motion_speed
    fan, _ = fit_to_flight(flight, Config().with_values(sensor={"speed": 6.0}))
    assert fan.pose_graph.motion_speed == Config().pose_graph.motion_speed
