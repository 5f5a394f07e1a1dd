// S3's XML answers (ListObjectsV2 pages, errors) read with Expat into a small tree. Private to
// the store.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "vts/base/result.hpp"

namespace vts::store::detail {

// An element: its local name (any "prefix:" dropped), its text (character data directly inside
// it, concatenated) and its child elements in document order.
struct XmlNode {
  std::string name, text;
  std::vector<XmlNode> children;
  // The first child named `name`; null when there is none.
  const XmlNode* child(std::string_view name) const;
  // The text of the first child named `name`; empty when there is none.
  std::string child_text(std::string_view name) const;
};

// Parses a document of at most 64 elements deep. A document type declaration (and so any entity
// definition) is refused, so no entity can expand. corrupt, with Expat's reason and line,
// otherwise.
Result<XmlNode> parse_xml(std::string_view document);

// "Code: Message" of S3's <Error> document; empty when `body` is not one.
std::string s3_error_text(std::string_view body);
// The <Code> of S3's <Error> document; empty when `body` is not one.
std::string s3_error_code(std::string_view body);

}  // namespace vts::store::detail
