// One self-contained HTML page for a job (no external files): a summary table, the interactive 3D
// view when given (postproc/viewer.h, its only scripts), and a section per patch with its pictures
// (inline SVG), facts and files.
#pragma once
#include <string>
#include <utility>
#include <vector>

namespace flankcam {

struct HtmlSection {
  std::string heading;
  std::vector<std::string> warnings;                        // shown first, highlighted
  std::vector<std::pair<std::string, std::string>> facts;   // label, value
  std::vector<std::string> svgs;                            // inline SVG documents
  std::vector<std::string> files;                           // relative links
};

struct HtmlReport {
  std::string title;
  std::vector<std::string> intro;                           // paragraphs
  std::vector<std::string> columns;                         // summary table
  std::vector<std::vector<std::string>> rows;
  std::string viewer;                                       // viewer_html(...) or empty: no 3D view
  std::vector<HtmlSection> sections;
};

[[nodiscard]] std::string report_html(const HtmlReport& r);

}  // namespace flankcam
