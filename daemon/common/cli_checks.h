#pragma once
/// @file
/// Checks of command-line values shared by hullguardd and hullguard (CLI11).

#include <cmath>
#include <string>

#include <CLI/CLI.hpp>

namespace hg::cli {

/// The value must be a finite number: CLI11's ranges let NaN through, and an
/// infinite duration or position means nothing here.
inline const CLI::Validator kFinite(
    [](std::string& text) -> std::string {
      try {
        std::size_t used = 0;
        const double value = std::stod(text, &used);
        if (used == text.size() && std::isfinite(value)) return "";
      } catch (const std::exception&) {
        // Not a number at all: the option's own conversion reports it.
        return "";
      }
      return "'" + text + "' is not a finite number";
    },
    "FINITE");

}  // namespace hg::cli
