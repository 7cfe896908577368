#include "postproc/report_html.h"

#include "postproc/markup.h"

namespace flankcam {

namespace {
// An inline SVG without its XML prolog (the documents here have none) inside a figure.
std::string figure(const std::string& svg) { return "<figure>\n" + svg + "</figure>\n"; }
}  // namespace

std::string report_html(const HtmlReport& r) {
  std::string h = "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>" + markup_escape(r.title) +
                  "</title>\n<style>\n"
                  "body{font-family:sans-serif;margin:24px;color:#222;max-width:1400px}\n"
                  "table{border-collapse:collapse;margin:12px 0}\n"
                  "td,th{border:1px solid #bbb;padding:4px 8px;text-align:left;font-variant-numeric:tabular-nums}\n"
                  "th{background:#eef}\n"
                  ".warn{background:#fde2e2;border:1px solid #d55;padding:6px 10px;margin:6px 0}\n"
                  "figure{display:inline-block;vertical-align:top;margin:8px 16px 8px 0}\n"
                  "section{border-top:2px solid #1f3b63;margin-top:24px}\n"
                  "</style>\n</head>\n<body>\n<h1>" +
                  markup_escape(r.title) + "</h1>\n";
  for (const auto& p : r.intro) h += "<p>" + markup_escape(p) + "</p>\n";
  h += "<table>\n<tr>";
  for (const auto& c : r.columns) h += "<th>" + markup_escape(c) + "</th>";
  h += "</tr>\n";
  for (const auto& row : r.rows) {
    h += "<tr>";
    for (const auto& c : row) h += "<td>" + markup_escape(c) + "</td>";
    h += "</tr>\n";
  }
  h += "</table>\n" + r.viewer;
  for (const HtmlSection& s : r.sections) {
    h += "<section>\n<h2>" + markup_escape(s.heading) + "</h2>\n";
    for (const auto& w : s.warnings) h += "<div class=\"warn\">" + markup_escape(w) + "</div>\n";
    if (!s.facts.empty()) {
      h += "<table>\n";
      for (const auto& [k, v] : s.facts) h += "<tr><th>" + markup_escape(k) + "</th><td>" + markup_escape(v) + "</td></tr>\n";
      h += "</table>\n";
    }
    for (const auto& svg : s.svgs) h += figure(svg);
    if (!s.files.empty()) {
      h += "<p>Files:";
      for (const auto& f : s.files) h += " <a href=\"" + markup_escape(f) + "\">" + markup_escape(f) + "</a>";
      h += "</p>\n";
    }
    h += "</section>\n";
  }
  return h + "</body>\n</html>\n";
}

}  // namespace flankcam
