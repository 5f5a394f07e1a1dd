// XmlWriter (router_xml.hpp).
#include "router_xml.hpp"

#include <cassert>

#include "vts/base/file_io.hpp"

namespace vts {
inline namespace server {
namespace router_detail {

std::string xml_escape(std::string_view s) {
  // html_escape's entities are XML's too (&#39; for '); what XML 1.0 adds is that most control
  // characters cannot be written at all, even escaped.
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    if (static_cast<unsigned char>(c) < 0x20 && c != '\t' && c != '\n' && c != '\r') {
      out += "\xEF\xBF\xBD";  // U+FFFD
    } else {
      out.push_back(c);
    }
  }
  return html_escape(out);
}

XmlWriter::XmlWriter() : out_("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n") {}

void XmlWriter::start(std::string_view name, const Attr* first, const Attr* last) {
  out_.append(open_.size() * 2, ' ');
  out_ += '<';
  out_ += name;
  for (const Attr* a = first; a != last; ++a) {
    out_ += ' ';
    out_ += a->name;
    out_ += "=\"";
    out_ += xml_escape(a->value);
    out_ += '"';
  }
}

void XmlWriter::open(std::string_view name, std::initializer_list<Attr> attrs) {
  start(name, attrs.begin(), attrs.end());
  out_ += ">\n";
  open_.emplace_back(name);
}

void XmlWriter::open(std::string_view name, const std::vector<Attr>& attrs) {
  start(name, attrs.data(), attrs.data() + attrs.size());
  out_ += ">\n";
  open_.emplace_back(name);
}

void XmlWriter::leaf(std::string_view name, std::string_view text) {
  start(name, nullptr, nullptr);
  out_ += '>';
  out_ += xml_escape(text);
  out_ += "</";
  out_ += name;
  out_ += ">\n";
}

void XmlWriter::empty(std::string_view name, std::initializer_list<Attr> attrs) {
  start(name, attrs.begin(), attrs.end());
  out_ += "/>\n";
}

void XmlWriter::close() {
  assert(!open_.empty());
  const std::string name = std::move(open_.back());
  open_.pop_back();
  out_.append(open_.size() * 2, ' ');
  out_ += "</" + name + ">\n";
}

std::string XmlWriter::finish() {
  assert(open_.empty());
  return std::move(out_);
}

}  // namespace router_detail
}  // namespace server
}  // namespace vts
