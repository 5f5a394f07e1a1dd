// A small XML writer for the WMTS documents (router_wmts.cpp): elements opened and closed in
// order, text and attribute values escaped, indented two spaces a level. Pure.
#pragma once

#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

namespace vts {
inline namespace server {
namespace router_detail {

// `s` with &, <, >, " and ' written as entities: safe as element text and as a double-quoted
// attribute value. Bytes below 0x20 but tab, newline and carriage return cannot appear in XML
// 1.0 at all: each is written as U+FFFD.
std::string xml_escape(std::string_view s);

class XmlWriter {
 public:
  struct Attr {
    std::string_view name, value;
  };
  XmlWriter();  // starts with the XML declaration (UTF-8)
  void open(std::string_view name, std::initializer_list<Attr> attrs = {});
  void open(std::string_view name, const std::vector<Attr>& attrs);
  // <name attrs>text</name>
  void leaf(std::string_view name, std::string_view text);
  // <name attrs/>
  void empty(std::string_view name, std::initializer_list<Attr> attrs);
  // Closes the innermost open element.
  void close();
  // The document; every element must be closed (asserted).
  std::string finish();

 private:
  void start(std::string_view name, const Attr* first, const Attr* last);
  std::string out_;
  std::vector<std::string> open_;
};

}  // namespace router_detail
}  // namespace server
}  // namespace vts
