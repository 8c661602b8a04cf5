// Reading the SVG that `--plot` writes, for tests: parsed by libxml2 (so it must be well-formed
// XML), then searched by element name and class as a reviewer's eye would: the title, the
// panels, the tick labels, the legend boxes, the unit circle, the marked eigenvalues.
#pragma once

#include <libxml/parser.h>
#include <libxml/tree.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace teleop::test {

struct SvgElement {
  std::string name{};
  std::map<std::string, std::string> attrs{};
  std::string text{};  // all text below it
  std::vector<SvgElement> children{};

  [[nodiscard]] bool has_class(const std::string& c) const {
    const auto it = attrs.find("class");
    if (it == attrs.end()) return false;
    std::istringstream words(it->second);
    std::string w;
    while (words >> w) {
      if (w == c) return true;
    }
    return false;
  }
  [[nodiscard]] double num(const std::string& attr) const {
    const auto it = attrs.find(attr);
    if (it == attrs.end()) throw std::runtime_error("<" + name + "> has no " + attr);
    return std::stod(it->second);
  }
  // Every element below (and including) this one that `pred` accepts, in document order.
  void find(const std::function<bool(const SvgElement&)>& pred,
            std::vector<const SvgElement*>& out) const {
    if (pred(*this)) out.push_back(this);
    for (const SvgElement& c : children) c.find(pred, out);
  }
  [[nodiscard]] std::vector<const SvgElement*> with_class(const std::string& c) const {
    std::vector<const SvgElement*> out;
    find([&](const SvgElement& e) { return e.has_class(c); }, out);
    return out;
  }
  [[nodiscard]] std::vector<const SvgElement*> named(const std::string& n) const {
    std::vector<const SvgElement*> out;
    find([&](const SvgElement& e) { return e.name == n; }, out);
    return out;
  }
};

namespace detail {
inline SvgElement convert(xmlNode* node) {
  SvgElement e;
  e.name = reinterpret_cast<const char*>(node->name);
  for (xmlAttr* a = node->properties; a != nullptr; a = a->next) {
    xmlChar* v = xmlNodeListGetString(node->doc, a->children, 1);
    e.attrs[reinterpret_cast<const char*>(a->name)] = v ? reinterpret_cast<const char*>(v) : "";
    xmlFree(v);
  }
  xmlChar* text = xmlNodeGetContent(node);
  e.text = text ? reinterpret_cast<const char*>(text) : "";
  xmlFree(text);
  for (xmlNode* c = node->children; c != nullptr; c = c->next) {
    if (c->type == XML_ELEMENT_NODE) e.children.push_back(convert(c));
  }
  return e;
}
}  // namespace detail

// Throws std::runtime_error when `text` is not well-formed XML with an <svg> root.
inline SvgElement parse_svg(const std::string& text) {
  xmlDoc* doc = xmlReadMemory(text.data(), static_cast<int>(text.size()), "plot.svg", nullptr,
                              XML_PARSE_NONET | XML_PARSE_NOERROR | XML_PARSE_NOWARNING);
  if (doc == nullptr) throw std::runtime_error("the SVG is not well-formed XML");
  SvgElement root = detail::convert(xmlDocGetRootElement(doc));
  xmlFreeDoc(doc);
  if (root.name != "svg") throw std::runtime_error("the root element is <" + root.name + ">");
  return root;
}

inline SvgElement read_svg(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error("cannot read " + path);
  std::ostringstream s;
  s << f.rdbuf();
  return parse_svg(s.str());
}

// The step of a tick set is round: 1, 2 or 5 times a power of ten.
inline bool round_step(double step) {
  if (!(step > 0.0)) return false;
  const double mantissa = step / std::pow(10.0, std::floor(std::log10(step) + 1e-9));
  for (const double m : {1.0, 2.0, 5.0, 10.0}) {
    if (std::abs(mantissa - m) < 1e-6) return true;
  }
  return false;
}

// Tick labels (numbers) in document order; false when one is not a number.
inline bool tick_values(const std::vector<const SvgElement*>& ticks, std::vector<double>& out) {
  for (const SvgElement* t : ticks) {
    std::size_t used = 0;
    try {
      out.push_back(std::stod(t->text, &used));
    } catch (const std::exception&) {
      return false;
    }
    if (used != t->text.size()) return false;
  }
  return true;
}

}  // namespace teleop::test
