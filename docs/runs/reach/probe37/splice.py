"""Splice a policy file: actor (policy.*) + obs_norm from A, critic (value.*) + value_norm from B.
python3 splice.py A_STEM B_STEM OUT_DIR   (stems without extension; writes OUT_DIR/policy.*)"""
import json,struct,sys,os
def fnv(b):
    h=0xcbf29ce484222325
    for x in b: h=((h^x)*0x100000001b3)&0xFFFFFFFFFFFFFFFF
    return h
def load(stem):
    m=json.load(open(stem+".json")); d=os.path.dirname(stem)
    raw=open(os.path.join(d,m['weights_file']),'rb').read()
    n=struct.unpack('<Q',raw[:8])[0]; h=json.loads(raw[8:8+n])
    return m,raw,n,h
ma,ra,na,ha=load(sys.argv[1]); mb,rb,nb,hb=load(sys.argv[2])
assert na==nb and ha==hb, "layouts differ"
out=bytearray(ra); base=8+na
for k,v in ha.items():
    if k.startswith('value.'):
        s,e=v['data_offsets']; out[base+s:base+e]=rb[base+s:base+e]
out=bytes(out); f="%016x"%fnv(out)
od=sys.argv[3]; os.makedirs(od,exist_ok=True)
name="policy.%s.safetensors"%f
open(os.path.join(od,name),'wb').write(out)
ma['weights_file']=name; ma['weights_fnv1a64']=f; ma['weights_len']=len(out)
ma['payload']['value_norm']=mb['payload']['value_norm']
json.dump(ma,open(os.path.join(od,"policy.json"),'w'))
print(od,name,"changed value bytes:",sum(1 for i in range(len(out)) if out[i]!=ra[i]))
