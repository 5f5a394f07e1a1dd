#include "s3_xml.hpp"

#include <expat.h>

#include <limits>
#include <memory>

namespace vts::store::detail {
namespace {

constexpr std::size_t kMaxXmlDepth = 64;

struct XmlBuilder {
  XML_Parser parser = nullptr;
  XmlNode root;                 // a synthetic parent of the document element
  std::vector<XmlNode*> stack;  // open elements, innermost last
  std::string refused;          // why parsing was stopped by us
};

void stop(XmlBuilder* b, const char* why) {
  if (b->refused.empty()) b->refused = why;
  XML_StopParser(b->parser, XML_FALSE);
}

void XMLCALL on_start(void* user, const XML_Char* name, const XML_Char** /*attributes*/) {
  auto* b = static_cast<XmlBuilder*>(user);
  if (b->stack.size() >= kMaxXmlDepth) return stop(b, "elements nested too deep");
  std::string_view n(name);
  if (const std::size_t colon = n.rfind(':'); colon != std::string_view::npos) {
    n.remove_prefix(colon + 1);
  }
  XmlNode* parent = b->stack.back();
  parent->children.push_back(XmlNode{std::string(n), {}, {}});
  b->stack.push_back(&parent->children.back());
}

void XMLCALL on_end(void* user, const XML_Char* /*name*/) {
  static_cast<XmlBuilder*>(user)->stack.pop_back();
}

void XMLCALL on_text(void* user, const XML_Char* s, int len) {
  auto* b = static_cast<XmlBuilder*>(user);
  if (len > 0) b->stack.back()->text.append(s, static_cast<std::size_t>(len));
}

void XMLCALL on_doctype(void* user, const XML_Char*, const XML_Char*, const XML_Char*, int) {
  stop(static_cast<XmlBuilder*>(user), "a document type declaration (refused)");
}

struct ParserFree {
  void operator()(XML_Parser p) const { XML_ParserFree(p); }
};

}  // namespace

const XmlNode* XmlNode::child(std::string_view n) const {
  for (const XmlNode& c : children) {
    if (c.name == n) return &c;
  }
  return nullptr;
}

std::string XmlNode::child_text(std::string_view n) const {
  const XmlNode* c = child(n);
  return c == nullptr ? std::string{} : c->text;
}

Result<XmlNode> parse_xml(std::string_view document) {
  if (document.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
    return make_error(ErrorCode::too_large, "XML document over 2 GiB");
  }
  std::unique_ptr<XML_ParserStruct, ParserFree> parser(XML_ParserCreate(nullptr));
  if (!parser) return make_error(ErrorCode::internal, "XML_ParserCreate failed");
  XmlBuilder b;
  b.parser = parser.get();
  b.stack.push_back(&b.root);
  XML_SetUserData(parser.get(), &b);
  XML_SetElementHandler(parser.get(), &on_start, &on_end);
  XML_SetCharacterDataHandler(parser.get(), &on_text);
  XML_SetDoctypeDeclHandler(parser.get(), &on_doctype, nullptr);
  const XML_Status st =
      XML_Parse(parser.get(), document.data(), static_cast<int>(document.size()), XML_TRUE);
  if (!b.refused.empty()) return make_error(ErrorCode::corrupt, "XML: " + b.refused);
  if (st != XML_STATUS_OK) {
    return make_error(ErrorCode::corrupt,
                      std::string("XML: ") + XML_ErrorString(XML_GetErrorCode(parser.get())) +
                          " at line " + std::to_string(XML_GetCurrentLineNumber(parser.get())));
  }
  if (b.root.children.size() != 1) return make_error(ErrorCode::corrupt, "XML: no root element");
  return std::move(b.root.children.front());
}

std::string s3_error_code(std::string_view body) {
  Result<XmlNode> doc = parse_xml(body);
  if (!doc || doc->name != "Error") return {};
  return doc->child_text("Code");
}

std::string s3_error_text(std::string_view body) {
  Result<XmlNode> doc = parse_xml(body);
  if (!doc || doc->name != "Error") return {};
  std::string code = doc->child_text("Code"), message = doc->child_text("Message");
  if (code.empty()) return message;
  return message.empty() ? code : code + ": " + message;
}

}  // namespace vts::store::detail
