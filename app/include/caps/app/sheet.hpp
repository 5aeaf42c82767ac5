#pragma once
/// @brief The operating-room sheet of a plan, `caps plan sheet`: one printable page (PDF, and
/// a PNG of the same page) with the incision drawn 1:1 on a flattened view of the skin around
/// it, each key point of the incision given as distances from landmarks a surgeon can palpate,
/// the closure's predicted forces and feature distortions when a result is given, and the
/// patient's and the plan's identity (docs/plan.md, "The operating-room sheet").
///
/// The flattened view (the sheet's paper coordinates, mm): the skin around the plan's centre
/// laid flat as caps walks on it (plan/skin_walk.hpp): the paper point at distance d in the
/// direction u from the centre is the skin point reached by walking d mm of skin from the
/// centre in the direction u of the skin's tangent plane there, on the line straight in the
/// head's cylinder coordinates (a geodesic where the skin is a cylinder). Up on the paper is the
/// patient's superior, right the patient's left (as when facing the patient). Distances from the
/// centre are skin distances exactly. The cut's key points are then laid on the paper keeping
/// their skin distances to each other (its lines first) as well as a plane can; the sheet states
/// the largest difference from the skin lengths and from the flattened view under them.

#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/core/reporter.hpp"

namespace caps::app {

struct SheetRequest {
  std::string plan, model, result, output;
  std::string paper = "a4";
  bool png = false, force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.plan, {"plan", "the plan file", FieldKind::Positional, "PLAN"});
    v(r.model, {"model", "the model directory (default: the one the plan names)"});
    v(r.result, {"result", "the folder caps simulate wrote for this plan: its predicted forces "
                           "and feature distortions go on the sheet"});
    v(r.paper, {"paper", "a4 (210 x 297 mm) or letter (8.5 x 11 in)"});
    v(r.output, {"output", "the sheet to write (.pdf)", FieldKind::Required, "-o,--output"});
    v(r.png, {"png", "also write the same page as a PNG (150 dpi) beside it, SHEET.png",
              FieldKind::Flag});
    v(r.force, {"force", "replace an existing sheet (and its PNG)", FieldKind::Flag});
  }
};

/// What `caps plan sheet` wrote and what is on it. Positions on the page are mm from its
/// top-left corner; points on the skin are (theta deg, z mm) of the model and LPS mm.
struct SheetResult {
  std::string output;  ///< the PDF written
  std::string png;     ///< the PNG written beside it (empty without --png)
  std::string paper;   ///< "A4" or "Letter"
  double page_width_mm = 0, page_height_mm = 0;
  /// The 1:1 drawing's frame on the page (top-left corner, size; mm) and the paper point (mm
  /// right, mm up from the plan's centre) at its top-left corner.
  double view_x_mm = 0, view_y_mm = 0, view_width_mm = 0, view_height_mm = 0;
  double view_left_mm = 0, view_top_mm = 0;
  /// The 10 mm scale bar: its left end and the height of its centre line on the page (mm).
  double scale_bar_x_mm = 0, scale_bar_y_mm = 0, scale_bar_mm = 10;
  /// The key points [{label, kind, theta_deg, z_mm, lps, paper_mm, landmarks: [{name, skin_mm,
  /// straight_mm, walk_mm, left_mm, up_mm}]}]: skin_mm the shortest path on the skin from the
  /// landmark (a geodesic; a tape held to the skin), straight_mm a straight line (a caliper's),
  /// walk_mm the walk caps plan new --at LANDMARK+LEFT,UP makes to the point (straight in the
  /// head's cylinder coordinates; at least skin_mm), left_mm and up_mm its components (the
  /// patient's left, superior along the skin).
  std::string points_json = "[]";
  std::vector<std::string> landmarks;  ///< the landmarks the distances are from, nearest first
  /// The largest difference between a line of the cut on paper and on the skin (mm), and how
  /// far the cut, laid at its skin lengths, sits from where the flattened view puts it (mm).
  double max_segment_error_mm = 0, max_offset_mm = 0;
  /// From --result: the closing force (the suture pairs' forces added), the largest force on a
  /// suture at the simulation's spacing (N), and the feature lines' displacements (JSON array
  /// of caps simulate's "features"; empty array where the result does not record them).
  bool has_result = false;
  double closing_force_n = 0, max_suture_force_n = 0, suture_spacing_mm = 0;
  int sutures = 0;
  std::string features_json = "[]";
  bool features_recorded = false;
  std::vector<std::string> warnings;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the PDF written"});
    v(r.png, {"png", "the PNG of the same page (empty: none)"});
    v(r.paper, {"paper"});
    v.pair(r.page_width_mm, r.page_height_mm, {"page_mm", "the page's width and height (mm)"});
    v.group({"view", "the 1:1 drawing: its frame on the page (mm from the top-left corner) and "
                     "the skin point at that corner (mm right, mm up from the plan's centre)"},
            [&] {
              v.pair(r.view_x_mm, r.view_y_mm, {"page_mm"});
              v.pair(r.view_width_mm, r.view_height_mm, {"size_mm"});
              v.pair(r.view_left_mm, r.view_top_mm, {"skin_mm"});
            });
    v.group({"scale_bar", "the scale bar: its left end on the page (mm) and length (mm)"}, [&] {
      v.pair(r.scale_bar_x_mm, r.scale_bar_y_mm, {"page_mm"});
      v(r.scale_bar_mm, {"length_mm"});
    });
    v.json_value(r.points_json, {"points", "the incision's key points and their distances from "
                                           "the landmarks (mm)"});
    v(r.landmarks, {"landmarks"});
    v(r.max_segment_error_mm, {"max_segment_error_mm", "the largest difference between a segment "
                                                       "of the cut on paper and on the skin (mm)"});
    v(r.max_offset_mm, {"max_offset_mm", "how far the cut on paper sits from where the skin "
                                         "picture under it puts it (mm)"});
    v.when(r.has_result, [&] {
      v.group({"closure", "the closure's prediction (--result)"}, [&] {
        v(r.closing_force_n, {"closing_force_n", "the suture pairs' forces added (N)"});
        v(r.max_suture_force_n, {"max_suture_force_n", "the largest force on one suture at "
                                                       "the spacing (N)"});
        v(r.sutures, {"sutures"});
        v(r.suture_spacing_mm, {"suture_spacing_mm"});
        v(r.features_recorded, {"features_recorded", "whether the result records the feature "
                                                     "lines' displacements"});
        v.json_value(r.features_json, {"features"});
      });
    });
    v(r.warnings, {"warnings"});
  }
};
std::string to_json(const SheetResult& result);
std::string summary(const SheetResult& result);

/// Draws the plan's operating-room sheet and writes it as a one-page PDF (and with `png` the
/// same page as a PNG at 150 dpi). Throws InvalidInput, before anything is written, for an
/// output that is not a .pdf or exists without `force`, a plan or model that cannot be read, a
/// result folder without result.json, a paper that is neither a4 nor letter, or a plan too large
/// to draw 1:1 on the page.
SheetResult run_plan_sheet(const SheetRequest& request, Reporter* reporter = nullptr);

}  // namespace caps::app
