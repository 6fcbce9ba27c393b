#pragma once
// What errsep-plan writes for a scan plan (core/scan_plan.hpp): the proposal in words, the
// predicted u_S(x) as CSV and as a figure (gnuplot, beside the paper's (1, 1, 5) at the same dx
// and K), and the [scan] keys of the machine config (io/machine_config.hpp) that set the scan to
// it: dx_mm, s2, s3, s4, N, averages (and sensor_stage_origin_mm when the stage's positions were
// listed).  Each file is written atomically.
#include <filesystem>
#include <optional>
#include <string>

#include "errsep/core/scan_plan.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/plots.hpp"

namespace errsep::io {

/// A `[scan]` table with the plan's keys, ready to replace those keys of a machine config.  With
/// `with_origin` also sensor_stage_origin_mm (the stage position of configuration 1).
std::string scan_plan_toml(const core::ScanPlan& plan, bool with_origin);

/// The proposal, its predicted U and u_S, the (1, 1, 5) comparison, the runners-up and how the
/// search went, in lines of text (what errsep-plan prints).
std::string scan_plan_summary(const core::ScanPlan& plan);

/// x_mm, u_S_um, u_deviation_um [, u_S_baseline_um], with the configuration, σ, K, U and its
/// definition as metadata.
CsvTable scan_plan_table(const core::ScanPlan& plan);

/// The predicted u_S(x) (and u about the least-squares line) of the plan and of the baseline.
LinePlot scan_plan_plot(const core::ScanPlan& plan);

struct ScanPlanFiles {
  std::filesystem::path csv, toml, summary;
  std::optional<PlotFiles> plot;
};

/// Writes <dir>/plan.csv, <dir>/scan.toml, <dir>/plan.txt and, when `plot` is given,
/// <dir>/u_S.{png,svg,gp,dat} (creating dir).  Throws std::runtime_error naming the file on
/// failure (files written before it stay whole).
ScanPlanFiles write_scan_plan(const core::ScanPlan& plan, const std::filesystem::path& dir,
                              bool with_origin, const std::optional<PlotOptions>& plot);

}  // namespace errsep::io
