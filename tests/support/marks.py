"""Which tests carry the markers `slow`, `system` and `gui` (registered in setup.cfg
[tool:pytest] with --strict-markers).  `make test-fast` runs the suite without them
(`-m "not slow and not system and not gui"`, about a minute on the 2-core machine, every
package covered); `make test` runs everything, the gate CI keeps.

The markers are given here, by tests/conftest.py's pytest_collection_modifyitems, not in the
test files: one table to read and change, and the test files stay as their owners write
them.  tests/test_markers.py checks that every name below is a test that exists.

- **system**: the test runs a real system service: a private cupsd (tests/private_cups.py),
  avahi in network namespaces (tests/private_mdns.py).  SYSTEM: whole modules.
- **gui**: the operator GUI under Qt: every test that uses pytest-qt's `qtbot`, and GUI.
- **slow**: measured.  The whole suite on the 2-core machine (2026-11-28, shared with other
  engineers' runs: 1,233 tests, ~660 s of test time), then test-fast again once the day's
  new modules had landed (1,331 tests): a test function is slow when one of its cases took
  0.6 s or more (setup, call and teardown).  That leaves ~1,130 tests and ~60 s of test
  time for test-fast.  Measured again after a day of new modules (1,642 tests): test-fast
  had grown to 149 s; the 24 unmarked functions at 0.6 s or more (91 s between them, the
  two-printer crash soak 28 s) are slow now.  A new test runs in test-fast until it is
  measured; to measure again:

      .venv/bin/python -m pytest -q -p no:cacheprovider --junit-xml=/tmp/t.xml
      .venv/bin/python tests/support/marks.py /tmp/t.xml     # the unmarked ones >= 0.6 s
"""

from __future__ import annotations

import sys

ALL = "*"
#: test time (s) from which a test function is slow
SLOW_S = 0.6

SYSTEM = {
    "test_cups.py": "a private cupsd with wideprint's backend",
    "test_ipp_cups.py": "a private cupsd with driverless queues in front of the Printer Application",
    "test_ipp_dnssd.py": "avahi-daemon and dbus in private network namespaces",
}

GUI = {
    "test_gui.py": "the operator GUI (offscreen Qt) against real servers",
}

#: (test file, fixture) -> why every test using that fixture is slow: a module fixture that
#: takes seconds to start, paid by whichever of its tests runs first
SLOW_FIXTURES = {
    ("test_ipp.py", "ipp"): "wideprint serve --ipp with its Printer Applications (~5 s)",
}

#: test file -> the slow test functions (all their parametrized cases), or ALL; the
#: comment is the slowest case's measured time (s)
SLOW: dict[str, set[str] | str] = {
    "test_acceptance.py": {
        "test_file_corrupt_far_down_fails_its_job_cleanly",  # 0.7
        "test_cli_print_media_equals_cli_rip_planes",  # 2.2
        "test_cli_bad_file_fails_its_job_and_the_next_prints",  # 1.2
        "test_binary_cmyk_tiff_prints_bit_exact",  # 1.0
        "test_cli_report_counts_strokes_not_passes",  # 1.4
    },
    "test_api_hostile.py": {
        "test_a_head_trickled_byte_by_byte_is_cut_off",  # 1.0
        "test_many_hostile_clients_at_once",  # 2.1
        "test_keep_alive_connection_serves_several_requests_then_times_out",  # 1.1
        "test_requests_beyond_the_limit_get_503_at_once",  # 0.0
        "test_idle_and_half_open_connections_are_closed_after_the_timeout",  # 3.0
    },
    "test_api_outcomes.py": {
        "test_cancel_answers_202_until_the_job_has_stopped",  # 0.0
    },
    "test_api_slow_clients.py": {
        "test_slow_uploads_cannot_take_every_thread",  # 0.0
        "test_status_answers_within_100_ms_under_500_half_open_connections",  # 0.0
    },
    "test_batch.py": {
        "test_cli_job_ids_differ_between_runs",  # 1.6
        "test_emulator_outputs_are_refused_with_a_standalone_device",  # 1.9
        "test_standalone_media_names_differ_between_runs",  # 2.7
        "test_batch_of_formats_prints_every_file_bit_exact",  # 1.2
        "test_preview_alone_is_drawn_from_a_temporary_media",  # 0.9
    },
    "test_calibrate.py": {
        "test_feed_error_is_measured_and_corrected",  # 2.9
        "test_head_offsets_are_measured_and_corrected",  # 1.5
        "test_bidir_offset_is_measured_and_corrected",  # 2.2
        "test_dead_nozzles_are_found_exactly_and_printed_around",  # 1.5
    },
    "test_color.py": {
        "test_throughput_and_threads",  # 0.7
    },
    "test_compiled.py": {
        "test_print_rip_and_preview_run_without_numba",  # 7.6
        "test_compiled_and_jit_kernels_land_the_same_dots",  # 18.5
    },
    "test_conventions.py": {
        "test_serve_tells_systemd_it_is_ready_and_stopping",  # 0.8
    },
    "test_crash_points.py": {
        "test_a_copy_caught_by_a_crash_takes_its_feed_off_the_roll",  # 1.8
        "test_in_process_printer",  # 2.9
        "test_standalone_printer_outlives_the_server",  # 4.2
        "test_standalone_printer_power_cycled_while_the_server_was_down",  # 4.8
    },
    "test_cups_backend.py": {
        "test_something_else_on_the_port_stops_the_queue",  # 0.6
        "test_a_file_is_queued",  # 0.7
        "test_a_wrong_token_stops_the_queue_even_with_a_large_file",  # 0.7
    },
    "test_deadrows.py": {
        "test_the_dots_of_a_dead_row_go_to_its_neighbours",  # 0.6
        "test_the_scan_shows_the_deficit_within_ten_percent_over_a_few_rows",  # 0.7
        "test_a_one_pass_job_with_dead_nozzles_on_several_heads_prints_bit_exact",  # 0.6
    },
    "test_diffusion.py": {
        "test_shipped_screen_mask_is_reproducible_from_the_generator",  # 17.1
        "test_screen_mask_generator_small",  # 5.3
        "test_tuned_strength_is_reproducible",  # 0.9
        "test_shipped_modulation_mask_is_reproducible_from_the_generator",  # 20.4
        "test_no_threshold_mask_beats_the_nested_bound",  # 4.9
    },
    "test_disk_full.py": {
        "test_a_job_waits_for_space_then_prints_and_nothing_loops",  # 9.1
        "test_a_job_printing_when_the_disk_fills_ends_done_when_space_returns",  # 5.8
        "test_a_full_media_disk_does_not_wedge_the_emulated_printer",  # 2.6
        "test_print_says_when_its_media_file_could_not_be_written",  # 1.0
    },
    "test_documents.py": {
        "test_page_box",  # 0.6
        "test_endless_loop_is_killed",  # 2.6
        "test_memory_is_bounded_by_the_band_not_the_page",  # 1.5
        "test_rotation_turns_each_page",  # 0.8
        "test_pdf_eps_ps_render_the_same_page",  # 1.2
        "test_a_bad_document_fails_only_its_job",  # 1.4
        "test_pages_print_one_after_another_along_the_roll",  # 0.6
        "test_loop_only_when_rendering_is_killed_too",  # 2.5
        "test_document_prints_bit_exact_like_its_page_rendered_to_tiff",  # 5.8
        "test_colour_cmyk_kept_grey_to_k_rgb_through_the_rips_icc_path",  # 0.8
    },
    "test_emulator.py": {
        "test_data_stall_starves_a_fast_line_but_prints_exactly",  # 0.6
    },
    "test_fault_resume.py": ALL,  # 1 s in all
    "test_halftone.py": {
        "test_constant_density",  # 0.8
        "test_shipped_mask_is_reproducible_from_generator",  # 1.0
    },
    "test_headcare.py": {
        "test_the_server_does_head_care_between_jobs_and_caps_an_idle_printer",  # 1.6
        "test_printer_commands_from_the_command_line",  # 1.8
        "test_capping_during_a_pause_stops_the_drying",  # 6.2
        "test_spitting_keeps_a_long_paused_job_bit_exact",  # 2.7
        "test_skipping_the_spits_clogs_a_long_paused_job",  # 2.6
    },
    "test_hostile_files.py": ALL,  # 33 s in all
    "test_hotfolders.py": {
        "test_preset_folder_replaced_by_a_symlink_is_not_entered",  # 2.9
        "test_hard_links_are_refused",  # 1.4
        "test_writer_closing_between_chunks_gives_one_job",  # 4.1
        "test_many_files_one_job_each_and_no_orphan_copies",  # 4.1
        "test_names_that_cannot_be_named_go_to_failed_once",  # 2.0
        "test_done_replaced_by_a_symlink_while_the_job_prints",  # 1.5
        "test_symlinked_files_are_refused_never_followed",  # 1.9
        "test_done_or_failed_replaced_by_a_symlink_moves_nothing_outside",  # 1.5
        "test_file_replaced_while_its_job_waits_is_a_new_job",  # 2.5
    },
    "test_ink150.py": {
        "test_seamless_across_bands_through_the_rip",  # 10.6 (JIT)
        "test_k_is_vceds_k_bit_for_bit",  # 4.9 (JIT)
        "test_150_dpi_joint_is_nearer_300_dpi_at_the_same_ink",  # 2.6
        "test_tone_exact_on_mixed_tints",  # 1.7
        "test_a_150_dpi_mode_prints_with_joint_and_300_dpis_ink",  # the media-modes loop
    },
    "test_ipp.py": {
        "test_ipptool_ipp_everywhere_suite",  # 20.4
        "test_cancel_job_through_ipp_cancels_the_wideprint_job",  # 1.0
        "test_the_printer_application_is_not_built_or_pappl_missing_is_loud",  # 6.1
        "test_jpeg_prints_bit_exact_with_the_original_file",  # 1.2
        "test_printing_needs_the_token",  # 5.3
        "test_the_media_attributes_follow_the_paper_the_printer_measured",  # 16.5 (its own server)
    },
    "test_layers.py": {
        "test_no_import_circle_inside_a_package",  # 2.0
        "test_device_sim_sees_only_the_seam_and_itself",  # 0.7
        "test_no_device_sim_module_is_in_an_import_cycle",  # 0.7
        "test_only_the_application_knows_the_emulator",  # 1.5
        "test_rip_imports_no_driver_no_emulator_no_app",  # 1.0
    },
    "test_cut.py": {
        "test_camera_cutter_finds_the_marks_and_cuts_on_the_printed_contour",  # 17
        "test_cut_file_path_equals_the_pdf_path_on_the_sheet",  # 20 (the decal fixture: two prints)
        "test_registration_marks_are_k_only_where_the_cut_file_says",  # 0.1 (or the fixture)
        "test_print_server_keeps_the_cut_files_with_the_job",  # 8
        "test_no_ink_under_the_cut_path_on_the_media",  # 0.1 (or the decal fixture)
        "test_cut_path_lies_on_the_print_through_the_placement",  # 2.2
        "test_rotated_page_and_eps_go_through_ghostscript_as_printed",  # 22 (loaded machine)
        "test_layouts_carry_their_items_cut_paths_and_marks",  # 4.9
        "test_pages_follow_each_other_with_their_cut_paths",  # 5.4
        "test_skew_turns_the_print_on_the_scan_and_leaves_the_media",  # 15
    },
    "test_cut_submit.py": {
        "test_submit_writes_the_jobs_cut_files",  # 3.1
        "test_submit_cut_out_refuses_a_job_without_cut_paths",  # 1.2
    },
    "test_cut_text.py": {
        "test_text_in_a_cut_colour_is_cut_along_its_glyphs",  # 4.6
    },
    "test_layout.py": {
        "test_cli_nests_different_images_in_one_job_and_reports_the_media_saved",  # 1.0
        "test_registration_marks_and_label_lie_outside_the_image",  # 1.2
    },
    "test_linearise.py": {
        "test_the_emulator_reports_the_same_ink_per_m2_for_every_mode_and_pass_count",  # 0.7
        "test_ink_per_m2_is_the_same_in_every_dpi_mode_with_linearisation",  # 0.7
        "test_a_wedge_with_dot_gain_is_measured_and_its_curves_linearise_the_reprint",  # 1.7
    },
    "test_media.py": {
        "test_default_media_verifies_drift_fails_and_recalibrate_restores",  # 5.5
        "test_media_create_runs_the_loop_in_minutes",  # 45
        "test_every_dpi_mode_prints_the_same_colour",  # 120
        "test_charts_measured_outside_wideprint_are_waited_for",  # 2.3
        "test_a_media_made_from_scans_is_within_2_5",  # 240
    },
    "test_media_outside_scan.py": {
        "test_a_chart_scanned_by_the_shop_reads_as_the_emulated_scanner",  # 345 (the loop)
    },
    "test_load.py": {
        "test_one_strip_tiffs_uncompressed_by_rows_compressed_over_16_mb_through_libvips",  # 0.7
        "test_memory_bounded_for_tall_image",  # 8.2
    },
    "test_motion.py": {
        "test_the_thesis_line_from_the_command_line",  # 1.0
    },
    "test_nest_server.py": {
        "test_a_time_limit_starts_a_nest_with_what_there_is",  # 1.6
        "test_a_count_rule_nests_three_jobs_on_one_sheet_bit_exact",  # 2.6
    },
    "test_noisy_line.py": {
        "test_an_open_but_silent_port_is_exit_3",  # 1.1
    },
    "test_nozzle_cal.py": {
        "test_calibrate_nozzles_recovers_the_typical_machines_errors",  # 19.1 (its fixture)
        "test_hiding_reads_under_half_the_checkers_banding_on_that_machine",  # 27.5
        "test_hiding_plans_the_strokes_the_driver_feeds",  # 15.6
        "test_dead_nozzles_and_the_errors_are_written_together",  # 7.7
        "test_hiding_prints_the_same_dots_as_checker",  # 1.9
        "test_the_profile_keeps_a_whole_dated_measurement",  # 1.4
        "test_the_block_packer_plans_hiding_as_the_per_dot_kernel",  # 6.3
    },
    "test_pci.py": {
        "test_cli_print_through_the_emulated_card_equals_cli_rip",  # 2.5
        "test_chained_dma_with_a_deep_ring_links_many_descriptors",  # 1.1
    },
    "test_physical.py": {
        "test_scanner_geometry_rotation_scale_and_placement",  # 0.6
        "test_head_offset_moves_only_that_heads_dots",  # 0.7
    },
    "test_place.py": {
        "test_tall_image_memory_is_bounded",  # 8.6
    },
    "test_quality.py": {
        "test_a_known_feed_error_is_banding_of_its_period_and_amplitude",  # 11.4
        "test_the_report_runs_on_the_typical_and_tired_machines_scans",  # 18.6
        "test_the_shingle_mask_is_tone_exact_and_deterministic",  # 3.3
        "test_masks_print_bit_exact_on_the_perfect_printer",  # 1.5
    },
    "test_planes_format.py": {
        "test_numba_starts_without_scipy_linalg",  # 0.8
    },
    "test_plugin.py": {
        "test_plugin_from_an_outside_project",  # 3.5
        "test_the_sample_suite_passes",  # 3.2
    },
    "test_preview.py": {
        "test_the_streamed_preview_is_the_whole_one",  # 1.3
        "test_the_preview_of_a_quarter_square_metre_needs_little_memory",  # 1.3
        "test_fine_patterns_average_instead_of_aliasing",  # 0.7
        "test_memory_is_bounded_by_the_band_not_the_length",  # 14.0
    },
    "test_printer_api.py": {
        "test_printer_commands_on_a_real_link_keep_the_printer_state",  # 3.3
        "test_printer_commands_on_the_in_process_emulator",  # 1.9
    },
    "test_printers.py": ALL,  # 16 s in all
    "test_rolls.py": {
        "test_a_job_wider_than_the_paper_is_refused_naming_the_file_and_forced_is_billed_nothing",  # 3.8
        "test_every_feed_comes_off_the_roll_and_a_job_it_cannot_hold_is_held_not_half_printed",  # 4.0
        "test_printer_roll_commands",  # 0.8
    },
    "test_archive.py": {
        "test_hold_by_preset_then_release_with_estimate_and_quote",  # 6.9
        "test_a_done_job_is_reprinted_bit_exact_and_with_changed_settings",  # 4.8
        "test_rip_and_hold_prints_the_kept_planes_bit_exact",  # 7.7
        "test_archived_planes_are_reprinted_without_ripping_again",  # 5
    },
    "test_costs.py": {
        "test_report_costs_from_a_stated_price_list",  # 5.5
    },
    "test_rtl.py": {
        "test_decoding_speed_is_per_row_not_per_pixel",  # 1.3
        "test_cli_prints_rtl_by_content_whatever_its_name",  # 2.4
    },
    "test_scancheck.py": {
        "test_a_scan_of_another_job_is_refused_at_registration",  # 3.4
        "test_the_emulators_own_scan_matches_the_prediction",  # 2.9
        "test_a_dead_nozzle_fails_with_the_row_it_left",  # 3.2
        "test_a_bidirectional_error_fails_with_the_shifted_rows",  # 1.5
        "test_the_plugin_compares_the_scan_given_on_the_command_line",  # 10.0
    },
    "test_server.py": {
        "test_thousand_concurrent_submissions_accepted_once_in_order",  # 12.4
        "test_a_printer_fault_stops_the_printer_not_the_queue",  # 1.6
        "test_presets_reread_when_the_file_changes_and_a_broken_file_is_refused",  # 2.9
        "test_cli_submit_queue_status",  # 0.8
        "test_hot_folder_slow_copy_becomes_one_job_when_complete",  # 5.1
        "test_server_killed_mid_job_resumes_bit_exact",  # 9.5
        "test_requeue_a_cancelled_job_prints_it_again_bit_exact",  # 1.0
        "test_presets_reload_says_what_changed",  # 0.9
        "test_spool_copies_of_ended_jobs_expire",  # 1.5
        "test_hot_folder_corrupt_file_goes_to_failed_with_reason",  # 1.1
        "test_accounting_csv_columns_and_values",  # 0.7
        "test_rtl_in_a_hot_folder_and_a_hostile_postscript_job",  # 1.7
        "test_corrupt_image_fails_its_job_alone",  # 1.2
        "test_hold_release_cancel_and_priority",  # 0.8
        "test_hot_folder_ignores_partial_names_until_renamed",  # 2.0
    },
    "test_spectral.py": {
        "test_observer_matches_colour_science",  # 0.8
        "test_flat_patches_equal_the_model",  # 17.9
    },
    "test_spot.py": {
        "test_printed_spots_measure_within_2_de2000_and_the_cut_line_drops_nothing",  # 3.0
        "test_pdf_spots_print_their_recipes_and_others_their_alternate",  # 2.7
        "test_postscript_spots_go_the_same_way",  # 1.9
        "test_devicen_mixes_library_recipes_and_process_inks",  # 0.9
        "test_cut_colour_in_forms_text_and_fill_and_stroke",  # 0.9
        "test_a_program_setting_its_spot_at_every_object_probes_each_name_once",  # 1.5
        "test_a_cut_line_neither_prints_nor_knocks_out",  # 1.1
        "test_a_document_without_library_or_cut_colours_is_not_rewritten",  # 0.9
        "test_swatch_book_round_trip",  # 0.8
        "test_cli_import_export_round_trip_and_name_matching",  # 0.8
        "test_resolution_through_the_media_profile_reports_the_gamut",  # 0.7
    },
    "test_spot_devicen.py": {
        "test_a_devicen_mixing_a_library_colour_with_an_unknown_one",  # 2.1
    },
    "test_spot_server.py": {
        "test_ripped_ahead_and_layout_jobs_record_their_spots",  # 3.2
        "test_a_printed_job_records_its_spots_from_the_servers_state_dir",  # 1.0
    },
    "test_standalone.py": ALL,  # 4 s in all
    "test_state_dir.py": {
        "test_a_lost_database_is_refused_and_the_spool_kept",  # 0.7
        "test_check_reports_and_repair_rebuilds_the_queue_held",  # 2.1
        "test_a_damaged_spool_copy_fails_its_job_naming_the_file",  # 0.8
    },
    "test_swath.py": {
        "test_every_dot_fired_once_by_a_live_nozzle",  # 4.9
    },
    "test_web.py": {
        "test_the_page_in_chromium_signs_in_follows_live_holds_releases_and_prints",  # 12.4
    },
    "test_soak.py": {
        "test_crash_soak_two_printers_three_clients_random_kills",  # 27.8
    },
    "test_hiding.py": {
        "test_hiding_halves_the_typical_machines_banding_on_whole_step_feeds",  # 9.7
        "test_stroke_hiding_halves_the_typical_machines_banding_on_the_default_feed",  # ~30
    },
    "test_roll_warning.py": {
        "test_ipp_says_media_low_as_a_warning_the_printer_goes_on",  # 6.1
        "test_the_warning_comes_before_the_job_that_would_run_off_is_held",  # 4.9
        "test_the_web_page_shows_the_warning_on_the_printers_card",  # 1.4
    },
    "test_fit_intake.py": {
        "test_an_ipp_print_job_wider_than_the_paper_ends_aborted_naming_it",  # 5.8
    },
    "test_parallel.py": {
        "test_the_planes_are_the_same_with_1_2_and_4_workers",  # 3.0
    },
    "test_banding_floor.py": {
        "test_the_perfect_printer_reads_no_banding_but_the_estimators_noise",  # 2.8
    },
    "test_chart_scan.py": {
        "test_a_turned_shifted_chart_reads_as_a_straight_one",  # 1.2
    },
    "test_cut_spots_report.py": {
        "test_a_print_and_cut_job_reports_its_spots",  # 1.2
    },
    "test_media_job.py": {
        "test_a_server_job_prints_its_media_as_the_command_line_does",  # 1.1
    },
    "test_support.py": {
        "test_test_files_import_helpers_from_support_only",  # 1.1
    },
    "test_softproof.py": {
        "test_the_proof_is_what_the_spectrophotometer_measures_on_the_print",  # 0.9
    },
    "test_markers.py": {
        "test_every_name_in_the_tables_is_a_test_that_exists",  # 0.9
        "test_the_fast_run_still_reaches_every_package",  # 0.8
    },
    "test_auth.py": {
        "test_a_user_acts_on_own_jobs_only",  # 0.6
    },
}


def markers_for(module: str, function: str, fixtures=()) -> list[str]:
    """The markers of the test `function` of the test file `module` (a file name)."""
    out = []
    slow = SLOW.get(module, ())
    if slow == ALL or function in slow or any((module, f) in SLOW_FIXTURES for f in fixtures):
        out.append("slow")
    if module in SYSTEM:
        out.append("system")
    if module in GUI or "qtbot" in fixtures:
        out.append("gui")
    return out


def main(argv: list[str]) -> int:
    """The test functions of a JUnit XML report (`pytest --junit-xml`) that took SLOW_S or
    more in some case and carry none of the markers: candidates for SLOW."""
    import xml.etree.ElementTree as ET
    if len(argv) != 1:
        print("usage: python tests/support/marks.py REPORT.xml", file=sys.stderr)
        return 2
    worst: dict[tuple[str, str], float] = {}
    for case in ET.parse(argv[0]).iter("testcase"):
        module = case.get("classname", "").split(".")[-1] + ".py"
        function = case.get("name", "").split("[")[0]
        key = (module, function)
        worst[key] = max(worst.get(key, 0.0), float(case.get("time", 0)))
    found = sorted((t, m, f) for (m, f), t in worst.items() if t >= SLOW_S and not markers_for(m, f))
    for t, m, f in reversed(found):
        print(f"{t:6.2f} s  {m}::{f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
