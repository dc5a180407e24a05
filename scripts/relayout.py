"""Layout-only re-wraps of Python modules to the 120-column limit (issue 75 point 6), checked per file.

Usage: ``python scripts/relayout.py MODE FILE...`` with MODE one of quotes (a multi-line docstring's closing quotes
onto its last prose or list line), wrap (docstring prose paragraphs re-filled), items (hanging-indent list items and
argument descriptions), deep (paragraphs under a heading), comments (full-line comment runs), join (a statement on one
line where it fits), pack (an argument list broken at one bracket packed), inner (a bracketed part joined onto its
line), strings (implicitly concatenated string pieces re-packed). No word changes: inline literals, number-and-unit
pairs, reference words (eq., Table, §) and operator operands stay together; tables, literal blocks, equation lines,
trailing-comma lists and aligned layouts are left alone. Each changed file is kept only when ``ast.dump`` of the module
with docstrings emptied is identical before and after and ``ruff check`` passes; otherwise it is restored and listed.
Do not run it on generated files (hindrax_common/config/typed_sections.py).
"""
import ast
import io
import re
import subprocess
import sys
import tokenize

W = 120
PY = sys.executable


def strip_docs(tree):
    """``ast.dump`` of ``tree`` with every docstring emptied."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            b = node.body
            if b and isinstance(b[0], ast.Expr) and isinstance(b[0].value, ast.Constant) \
                    and isinstance(b[0].value.value, str):
                b[0].value.value = ""
    return ast.dump(tree)


def docstring_nodes(tree):
    """The docstring constants of a module, its classes and functions."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            b = node.body
            if b and isinstance(b[0], ast.Expr) and isinstance(b[0].value, ast.Constant) \
                    and isinstance(b[0].value.value, str):
                yield b[0].value


BAD_START = ("|", "+-", "+=", "==", "--", ">>>", "..", "```")
LIST_RE = re.compile(r"^([-*•] |\d+[.)] |\(\w+\) )")


def ind(s):
    """Indentation width of line ``s``."""
    return len(s) - len(s.lstrip())


def quotes(src):
    """Closing quotes of multi-line docstrings moved onto the last line of prose or of a list item."""
    lines = src.split("\n")
    tree = ast.parse(src)
    for c in docstring_nodes(tree):
        s, e = c.lineno - 1, c.end_lineno - 1
        if s == e or lines[e].strip() != '"""':
            continue
        base = ind(lines[e])
        k = e - 1
        last = lines[k]
        if not last.strip() or k == s:
            continue
        # last paragraph
        p = k
        while p - 1 > s and lines[p - 1].strip():
            p -= 1
        para = lines[p:k + 1]
        if any(ln.strip().startswith(BAD_START) for ln in para):
            continue
        if ind(lines[p]) != base and p != s:
            continue
        if any(ln.rstrip().endswith("::") for ln in lines[s:k + 1]) and lines[p - 1].strip() == "" and \
                any(ln.rstrip().endswith("::") for ln in lines[s:p]) and _literal_before(lines, s, p, base):
            continue
        if last.rstrip().endswith(("\\", '"')) or "  " in last.strip():
            continue
        new = last.rstrip() + '"""'
        if len(new) > W:
            continue
        lines[k] = new
        lines[e] = None
    return "\n".join(ln for ln in lines if ln is not None)


def _literal_before(lines, s, p, base):
    # the last paragraph follows a paragraph ending in '::' -> literal block
    q = p - 1
    while q > s and not lines[q].strip():
        q -= 1
    return lines[q].rstrip().endswith("::")


def _open(w):
    """True while ``w`` holds an unclosed inline literal."""
    d = w.count("``")
    return d % 2 == 1 or (w.count("`") - 2 * d) % 2 == 1


NUM = re.compile(r"^[-+−~≈<>≤≥±(]*\d[\d.,]*(e[-+]?\d+)?([-–]\d[\d.,]*)?%?$")
REFW = {"eq.", "eqs.", "Eq.", "Eqs.", "Table", "Tables", "§", "Fig.", "Figs.", "ch.", "Ch.", "p.", "pp.", "No."}


def units(words):
    """Merge inline literals and number+unit pairs into unbreakable units."""
    out, i = [], 0
    while i < len(words):
        w = words[i]
        while _open(w) and i + 1 < len(words):
            i += 1
            w += " " + words[i]
        while w in REFW and i + 1 < len(words):
            i += 1
            w += " " + words[i]
        if NUM.match(w.split(" ")[-1]) and i + 1 < len(words):
            i += 1
            w += " " + words[i]
            while _open(w) and i + 1 < len(words):
                i += 1
                w += " " + words[i]
        out.append(w)
        i += 1
    # binary operators and mapping arrows stay with both operands
    res = []
    glue = False
    for w in out:
        if glue and res:
            res[-1] += " " + w
            glue = w in OPS
        elif w in OPS and res:
            res[-1] += " " + w
            glue = True
        else:
            res.append(w)
            glue = False
    return res


OPS = {"+", "-", "=", "*", "/", ".", "->", "<=", ">=", "<", ">", "==", "!=", "+=", "-=", "~", "≈", "x", "·", "×",
       "−", "^", "|", "→", "<-", "±", "+/-"}


def fill(prefix0, prefix, words, suffix=""):
    """Greedy fill of ``words`` to :data:`W` columns; the first line starts with ``prefix0``."""
    out, cur = [], prefix0
    first = True
    for w in words:
        if first:
            cur += w
            first = False
        elif len(cur) + 1 + len(w) <= W:
            cur += " " + w
        else:
            out.append(cur)
            cur = prefix + w
    out.append(cur + suffix)
    return out


def wrap(src):
    """Docstring prose paragraphs at the docstring's indentation re-filled to :data:`W` columns."""
    lines = src.split("\n")
    tree = ast.parse(src)
    repl = {}
    for c in docstring_nodes(tree):
        s, e = c.lineno - 1, c.end_lineno - 1
        if s == e:
            continue
        first = lines[s]
        m = re.match(r'^(\s*)([rRuU]?""")', first)
        if not m:
            continue
        base = ind(lines[s]) if s > 0 else 0
        # docstring lines: s..e ; content excludes the opening quotes
        # find paragraphs: maximal runs of non-blank lines at base indent, all prose
        i = s
        lit = False
        while i <= e:
            ln = lines[i]
            if not ln.strip() or ln.strip() == '"""':
                i += 1
                continue
            j = i
            while j + 1 <= e and lines[j + 1].strip() and lines[j + 1].strip() != '"""':
                j += 1
            block = lines[i:j + 1]
            prev_lit = lit
            lit = block[-1].rstrip().rstrip('"').rstrip().endswith("::")
            ok = not prev_lit and len(block) >= 2
            start_text = block[0][len(m.group(0)):] if i == s else block[0]
            if ok:
                for n, b in enumerate(block):
                    t = b.strip() if not (n == 0 and i == s) else start_text.strip()
                    if (n > 0 or i != s) and ind(b) != base:
                        ok = False
                    if t.startswith(BAD_START) or LIST_RE.match(t) or "  " in t or \
                            t.endswith("::") and n < len(block) - 1:
                        ok = False
                    if re.match(r"^[A-Z][A-Za-z ]*:$", t) or "\t" in b:
                        ok = False
                    if '"""' in t and not (n == len(block) - 1 and t.endswith('"""') and t.count('"""') == 1):
                        ok = False
                    if re.search(r"\s[=<>]\s|\S=\S", _nolit(t)) and not re.search(r"[a-z]{4,} [a-z]{4,} [a-z]{4,}", t):
                        ok = False  # looks like an equation line
                    if t.endswith(":") and n < len(block) - 1:
                        ok = False  # introduces something line by line
            if ok and deliberate(block):
                ok = False
            if ok:
                texts = [start_text.strip() if (n == 0 and i == s) else b.strip() for n, b in enumerate(block)]
                suffix = ""
                if texts[-1].endswith('"""'):
                    texts[-1] = texts[-1][:-3]
                    suffix = '"""'
                words = units(" ".join(texts).split(" "))
                prefix = " " * base
                prefix0 = first[:len(m.group(0))] if i == s else prefix
                new = fill(prefix0, prefix, words, suffix)
                if len(new) < len(block) and all(len(x) <= W for x in new):
                    repl[i] = (j, new)
            i = j + 1
    for i in sorted(repl, reverse=True):
        j, new = repl[i]
        lines[i:j + 1] = new
    return "\n".join(lines)


OPEN, CLOSE = "([{", ")]}"


def join(src):
    """Statements over several lines joined where the whole fits :data:`W` columns."""
    lines = src.split("\n")
    toks = list(tokenize.generate_tokens(io.StringIO(src).readline))
    # logical lines
    stmts, cur = [], []
    for t in toks:
        cur.append(t)
        if t.type in (tokenize.NEWLINE, tokenize.ENDMARKER) or (t.type == tokenize.NL and len(cur) == 1) or \
                (t.type == tokenize.COMMENT and len(cur) == 1):
            stmts.append(cur)
            cur = []
    edits = []
    for st in stmts:
        real = [t for t in st if t.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
                                                tokenize.ENDMARKER)]
        if not real:
            continue
        r0, r1 = real[0].start[0], real[-1].end[0]
        if r0 == r1:
            continue
        if any(t.start[0] != t.end[0] for t in real):
            continue  # multi-line string
        comments = [t for t in real if t.type == tokenize.COMMENT]
        if any(t.start[0] != r1 for t in comments):
            continue
        # backslash continuation: a physical line ending without NL token inside brackets
        nl_rows = {t.start[0] for t in st if t.type == tokenize.NL}
        if any(r not in nl_rows for r in range(r0, r1)):
            continue
        # magic trailing comma
        bad = False
        for a, b in zip(real, real[1:]):
            if a.string == "," and b.string in CLOSE and b.start[0] != a.start[0]:
                bad = True
            if a.type == tokenize.STRING and b.type == tokenize.STRING and a.start[0] != b.start[0]:
                bad = True
        if bad:
            continue
        phys = lines[r0 - 1:r1]
        if any("  " in p.strip() for p in phys[1:]) or "  " in phys[0].strip().split("#")[0]:
            continue  # aligned layout
        out = phys[0].rstrip()
        for p in phys[1:]:
            q = p.strip()
            if out[-1] in OPEN or q[0] in CLOSE or q[0] == ".":
                out += q
            else:
                out += " " + q
        if len(out) <= W:
            edits.append((r0, r1, out))
    for r0, r1, out in sorted(edits, reverse=True):
        lines[r0 - 1:r1] = [out]
    return "\n".join(lines)


def pack(src):
    """Argument lists broken at one bracket, continuation lines aligned on it, packed to :data:`W` columns."""
    lines = src.split("\n")
    toks = list(tokenize.generate_tokens(io.StringIO(src).readline))
    stmts, cur = [], []
    for t in toks:
        cur.append(t)
        if t.type in (tokenize.NEWLINE, tokenize.ENDMARKER) or (t.type == tokenize.NL and len(cur) == 1) or \
                (t.type == tokenize.COMMENT and len(cur) == 1):
            stmts.append(cur)
            cur = []
    edits = []
    for st in stmts:
        real = [t for t in st if t.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
                                                tokenize.ENDMARKER)]
        if not real:
            continue
        r0, r1 = real[0].start[0], real[-1].end[0]
        if r1 - r0 < 2:
            continue
        if any(t.start[0] != t.end[0] for t in real) or any(t.type == tokenize.COMMENT for t in real):
            continue
        nl_rows = {t.start[0] for t in st if t.type == tokenize.NL}
        if any(r not in nl_rows for r in range(r0, r1)):
            continue
        bad = False
        for a, b in zip(real, real[1:]):
            if a.string == "," and b.string in CLOSE and b.start[0] != a.start[0]:
                bad = True
            if a.type == tokenize.STRING and b.type == tokenize.STRING and a.start[0] != b.start[0]:
                bad = True
        if bad:
            continue
        # the innermost open bracket at every line break must be one and the same, opened on the first line
        stack, owners = [], set()
        for t in st:
            if t.type == tokenize.OP and t.string in OPEN:
                stack.append(t.start)
            elif t.type == tokenize.OP and t.string in CLOSE:
                stack.pop()
            elif t.type == tokenize.NL and stack:
                owners.add(stack[-1])
        if len(owners) != 1 or next(iter(owners))[0] != r0:
            continue
        phys = lines[r0 - 1:r1]
        if any("  " in p.strip() for p in phys[1:]) or "  " in phys[0].strip():
            continue
        col = next(iter(owners))[1] + 1
        own = next(iter(owners))
        idx = next(k for k, t in enumerate(st) if t.start == own and t.type == tokenize.OP)
        prev = st[idx - 1] if idx else None
        is_call = st[idx].string == "(" and prev is not None and (prev.type == tokenize.NAME and prev.string not in (
            "in", "and", "or", "not", "if", "else", "return", "yield", "for", "assert", "await", "lambda")
            or prev.string in ")]")
        is_all = st[idx].string == "[" and real[0].string == "__all__"
        if not (is_call or is_all):
            continue
        if any(re.match(r"(for|if|and|or|else|not)\b|[\[({]|[-+*/%@|&]", p.strip()) for p in phys[1:]):
            continue
        if any(ind(p) != col for p in phys[1:]):
            continue  # not aligned with the bracket: leave as it is
        out = [phys[0].rstrip()]
        for p in phys[1:]:
            q = p.strip()
            sep = "" if out[-1][-1] in OPEN or q[0] in CLOSE or q[0] == "." else " "
            if len(out[-1]) + len(sep) + len(q) <= W:
                out[-1] += sep + q
            else:
                out.append(" " * col + q)
        if len(out) < len(phys):
            edits.append((r0, r1, out))
    for r0, r1, out in sorted(edits, reverse=True):
        lines[r0 - 1:r1] = out
    return "\n".join(lines)


def deliberate(block):
    """True when a line of the block ends early: the next line's first word would have fitted on it."""
    longest = max(len(x.rstrip()) for x in block)
    for x, y in zip(block, block[1:]):
        w = y.strip().split(" ")[0]
        if len(x.rstrip()) + 1 + len(w) < longest - 8:
            return True
    return False


def _nolit(t):
    """``t`` with its inline literals replaced by a placeholder."""
    return re.sub(r"``.*?``|`[^`]*`", "L", t)


def line_ok(t):
    """False for a line that is a table row, code, a literal-block lead-in or an equation."""
    if t.startswith(BAD_START) or "  " in t or t.endswith("::") or "\t" in t:
        return False
    if re.search(r"\s[=<>]\s|\S=\S", _nolit(t)) and not re.search(r"[a-z]{4,} [a-z]{4,} [a-z]{4,}", t):
        return False
    return True


def items(src):
    """Hanging-indent items (argument descriptions, list items) re-filled to 120 columns."""
    lines = src.split("\n")
    tree = ast.parse(src)
    repl = {}
    for c in docstring_nodes(tree):
        s, e = c.lineno - 1, c.end_lineno - 1
        if s == e:
            continue
        i = s + 1
        lit_indent = None
        while i <= e:
            ln = lines[i]
            t = ln.strip()
            if not t or t == '"""':
                i += 1
                continue
            if lit_indent is not None:
                if ind(ln) > lit_indent:
                    i += 1
                    continue
                lit_indent = None
            if t.endswith("::") or t.endswith(':: """'):
                lit_indent = ind(ln)
                i += 1
                continue
            a = ind(ln)
            j = i
            while j + 1 <= e and lines[j + 1].strip() and lines[j + 1].strip() != '"""' and ind(lines[j + 1]) > a:
                j += 1
            item = lines[i:j + 1]
            i = j + 1
            if len(item) < 2:
                continue
            cont = {ind(x) for x in item[1:]}
            if len(cont) != 1:
                continue
            ci = cont.pop()
            first = item[0].strip()
            if not (LIST_RE.match(first) or re.match(r"^[\w.*, /`~:<>\[\]|-]+( \([^)]*\))?: ", first)):
                continue  # a definition-list term or a heading: its break is deliberate
            if first.endswith(":") or len(first) < 40 or '"""' in first[:-3]:
                continue
            texts = [x.strip() for x in item]
            if not all(line_ok(x) for x in texts):
                continue
            if any('"""' in x for x in texts[:-1]) or texts[-1].count('"""') > 1:
                continue
            if any(x.endswith(":") for x in texts[:-1]):
                continue
            if deliberate(item):
                continue
            suffix = ""
            if texts[-1].endswith('"""'):
                texts[-1] = texts[-1][:-3]
                suffix = '"""'
            words = units(" ".join(texts).split(" "))
            new = fill(" " * a, " " * ci, words, suffix)
            if len(new) < len(item) and all(len(x) <= W for x in new):
                repl[i - len(item)] = (i - 1, new)
    for k in sorted(repl, reverse=True):
        j, new = repl[k]
        lines[k:j + 1] = new
    return "\n".join(lines)


CMT = re.compile(r"^(\s*)(#:? )(\S.*)$")


def comments(src):
    """Runs of full-line comments (same indent, same marker) re-filled to 120 columns."""
    lines = src.split("\n")
    toks = list(tokenize.generate_tokens(io.StringIO(src).readline))
    full = set()
    for t in toks:
        if t.type == tokenize.COMMENT and lines[t.start[0] - 1].strip().startswith("#"):
            full.add(t.start[0] - 1)
    out, i = [], 0
    while i < len(lines):
        m = CMT.match(lines[i]) if i in full else None
        if not m:
            out.append(lines[i])
            i += 1
            continue
        j = i
        run = [m]
        while j + 1 < len(lines) and (j + 1) in full:
            m2 = CMT.match(lines[j + 1])
            if not m2 or m2.group(1) != m.group(1) or m2.group(2) != m.group(2):
                break
            run.append(m2)
            j += 1
        texts = [r.group(3) for r in run]
        ok = len(run) >= 2 and all(line_ok(t) and not LIST_RE.match(t) and not t.endswith(":") for t in texts[:-1])
        ok = ok and line_ok(texts[-1]) and not LIST_RE.match(texts[-1])
        ok = ok and not any(re.search(r"[^ ][/-]$", t) for t in texts[:-1])
        ok = ok and not any(re.match(r"(noqa|type:|pragma|fmt:|-\*-|isort|ruff)", t) for t in texts)
        if ok and deliberate(lines[i:j + 1]):
            ok = False
        if ok:
            words = units(" ".join(texts).split(" "))
            pre = m.group(1) + m.group(2)
            new = fill(pre, pre, words)
            if len(new) < len(run) and all(len(x) <= W for x in new):
                out.extend(new)
                i = j + 1
                continue
        out.extend(lines[i:j + 1])
        i = j + 1
    return "\n".join(out)


def inner(src):
    """Bracketed parts of a multi-line statement joined onto their first line where that fits 120 columns."""
    lines = src.split("\n")
    toks = list(tokenize.generate_tokens(io.StringIO(src).readline))
    stmts, cur = [], []
    for t in toks:
        cur.append(t)
        if t.type in (tokenize.NEWLINE, tokenize.ENDMARKER) or (t.type == tokenize.NL and len(cur) == 1) or \
                (t.type == tokenize.COMMENT and len(cur) == 1):
            stmts.append(cur)
            cur = []
    edits = []
    for st in stmts:
        real = [t for t in st if t.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
                                                tokenize.ENDMARKER)]
        if not real or real[0].start[0] == real[-1].end[0]:
            continue
        nl_rows = {t.start[0] for t in st if t.type == tokenize.NL}
        r0, r1 = real[0].start[0], real[-1].end[0]
        if any(r not in nl_rows for r in range(r0, r1)):
            continue
        # bracket pairs
        stack, pairs, open_at_eol = [], [], {}
        for k, t in enumerate(real):
            if t.type == tokenize.OP and t.string in OPEN:
                stack.append(k)
            elif t.type == tokenize.OP and t.string in CLOSE:
                o = stack.pop()
                if real[o].start[0] != t.start[0]:
                    pairs.append((o, k))
            nxt = real[k + 1] if k + 1 < len(real) else None
            if nxt is None or nxt.start[0] != t.end[0]:
                open_at_eol[t.end[0]] = [real[x].start for x in stack]
        pairs.sort(key=lambda p: real[p[0]].start[0] - real[p[1]].start[0])  # largest span first
        taken = set()
        for o, c in pairs:
            a, b = real[o].start[0], real[c].start[0]
            if any(r in taken for r in range(a, b + 1)):
                continue
            seg = [t for t in real if a <= t.start[0] <= b]
            if any(t.start[0] != t.end[0] for t in seg) or any(t.type == tokenize.COMMENT and t.start[0] != b
                                                                 for t in seg):
                continue
            bad = False
            for x, y in zip(seg, seg[1:]):
                if x.string == "," and y.string in CLOSE and y.start[0] != x.start[0]:
                    bad = True
                if x.type == tokenize.STRING and y.type == tokenize.STRING and x.start[0] != y.start[0]:
                    bad = True
            if bad:
                continue
            if any(pos[0] > a or (pos[0] == a and pos[1] > real[o].start[1]) for pos in open_at_eol.get(b, [])):
                continue  # a later line is aligned on a bracket that would move
            phys = lines[a - 1:b]
            if any("  " in p.strip() for p in phys[1:]) or "  " in phys[0].strip():
                continue
            out = phys[0].rstrip()
            for p in phys[1:]:
                q = p.strip()
                out += q if out[-1] in OPEN or q[0] in CLOSE or q[0] == "." else " " + q
            if len(out) <= W:
                edits.append((a, b, out))
                taken.update(range(a, b + 1))
    for a, b, out in sorted(edits, reverse=True):
        lines[a - 1:b] = [out]
    return "\n".join(lines)


SPFX = re.compile(r"^([rRbBuUfF]*)(['\"])(.*)\2$", re.S)


def _chunks(body, fstr):
    """Body source text split after each space outside f-string braces."""
    out, cur, depth = [], "", 0
    for ch in body:
        cur += ch
        if fstr and ch == "{":
            depth += 1
        elif fstr and ch == "}":
            depth = max(0, depth - 1)
        elif ch == " " and depth == 0:
            out.append(cur)
            cur = ""
    if cur:
        out.append(cur)
    return out


def strings(src):
    """Implicitly concatenated string pieces, one per line, re-packed to 120 columns; the text is unchanged."""
    lines = src.split("\n")
    toks = [t for t in tokenize.generate_tokens(io.StringIO(src).readline)
            if t.type not in (tokenize.NL, tokenize.INDENT, tokenize.DEDENT)]
    edits, k = [], 0
    while k < len(toks):
        t = toks[k]
        if t.type != tokenize.STRING:
            k += 1
            continue
        run = [t]
        while k + len(run) < len(toks):
            nx = toks[k + len(run)]
            pv = run[-1]
            if nx.type == tokenize.STRING and nx.start[0] == pv.end[0] + 1 and \
                    lines[nx.start[0] - 1][:nx.start[1]].strip() == "" and \
                    lines[pv.end[0] - 1][pv.end[1]:].strip() == "":
                run.append(nx)
            else:
                break
        k += len(run)
        if len(run) < 2:
            continue
        ms = [SPFX.match(x.string) for x in run]
        if not all(ms) or len({(m.group(1).lower(), m.group(2)) for m in ms}) != 1 or \
                any(x.start[0] != x.end[0] for x in run) or any(m.group(3).startswith(m.group(2) * 2) for m in ms):
            continue
        pfx, q = ms[0].group(1), ms[0].group(2)
        if len({x.start[1] for x in run[1:]}) != 1:
            continue
        col = run[1].start[1]
        a, b = run[0].start[0], run[-1].start[0]
        head = lines[a - 1][:run[0].start[1]]
        tail = lines[b - 1][run[-1].end[1]:]
        body = "".join(m.group(3) for m in ms)
        words = _chunks(body, "f" in pfx.lower())
        if any(w == " " or w.startswith(" ") for w in words):
            continue
        last_sp = words[-1].endswith(" ")
        merged = units([w[:-1] if w.endswith(" ") else w for w in words])
        words = [w + " " for w in merged[:-1]] + [merged[-1] + (" " if last_sp else "")]
        out, cur = [], head + pfx + q
        for w in words:
            if len(cur) + len(w) + 1 <= W or cur.endswith(pfx + q):
                cur += w
            else:
                out.append(cur + q)
                cur = " " * col + pfx + q + w
        cur += q + tail
        if len(cur) > W:
            continue
        out.append(cur)
        if len(out) < len(run) and all(len(x) <= W for x in out):
            edits.append((a, b, out))
    for a, b, out in sorted(edits, reverse=True):
        lines[a - 1:b] = out
    return "\n".join(lines)


def deep(src):
    """Paragraphs at one indent deeper than the docstring's (section bodies) re-filled to 120 columns."""
    lines = src.split("\n")
    tree = ast.parse(src)
    repl = {}
    for c in docstring_nodes(tree):
        s, e = c.lineno - 1, c.end_lineno - 1
        if s == e:
            continue
        base = ind(lines[e]) if lines[e].strip() == '"""' else None
        i = s + 1
        prev = lines[s]
        while i <= e:
            ln = lines[i]
            if not ln.strip() or ln.strip() == '"""':
                i += 1
                continue
            a = ind(ln)
            j = i
            while j + 1 <= e and lines[j + 1].strip() and lines[j + 1].strip() != '"""' and ind(lines[j + 1]) == a:
                j += 1
            block = lines[i:j + 1]
            prevline = prev
            prev = lines[j]
            i = j + 1
            if len(block) < 2 or (base is not None and a <= base) or a == 0:
                continue
            if prevline.rstrip().rstrip('"').rstrip().endswith("::") or ind(prevline) >= a and prevline.strip():
                continue
            # the block must follow a heading or an item line at a lower indent
            texts = [x.strip() for x in block]
            if not all(line_ok(t) and not LIST_RE.match(t) for t in texts):
                continue
            if any(t.endswith(":") for t in texts[:-1]) or any('"""' in t for t in texts[:-1]):
                continue
            if any(re.search(r"[^ ][/-]$", t) for t in texts[:-1]):
                continue
            if any(re.match(r"^[\w.*, `]+( \([^)]*\))?: ", t) for t in texts[1:]):
                continue  # one item per line (argument lists)
            if deliberate(block):
                continue
            suffix = ""
            if texts[-1].endswith('"""'):
                texts[-1] = texts[-1][:-3]
                suffix = '"""'
            words = units(" ".join(texts).split(" "))
            new = fill(" " * a, " " * a, words, suffix)
            if len(new) < len(block) and all(len(x) <= W for x in new):
                repl[i - len(block)] = (i - 1, new)
    for k in sorted(repl, reverse=True):
        j, new = repl[k]
        lines[k:j + 1] = new
    return "\n".join(lines)


def main():
    """Apply MODE to every FILE; print the lines cut and the files restored."""
    mode, files = sys.argv[1], sys.argv[2:]
    fn = {"quotes": quotes, "wrap": wrap, "join": join, "pack": pack, "items": items, "comments": comments,
          "inner": inner, "strings": strings, "deep": deep}[mode]
    total = 0
    failed = []
    for f in files:
        src = open(f).read()
        try:
            new = fn(src)
        except Exception as ex:  # noqa
            failed.append((f, f"transform error {ex!r}"))
            continue
        if new == src:
            continue
        try:
            same = strip_docs(ast.parse(src)) == strip_docs(ast.parse(new))
        except SyntaxError:
            same = False
        if not same:
            failed.append((f, "AST differs"))
            continue
        open(f, "w").write(new)
        r = subprocess.run([PY, "-m", "ruff", "check", "-q", f], capture_output=True, text=True)
        if r.returncode:
            open(f, "w").write(src)
            failed.append((f, "ruff: " + r.stdout[:300]))
            continue
        d = src.count("\n") - new.count("\n")
        total += d
    print(f"{mode}: {len(files)} files, {total} lines cut, {len(failed)} reverted")
    for f, why in failed:
        print("  REVERTED", f, why)


main()
